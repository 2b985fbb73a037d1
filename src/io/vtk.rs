//! Particle output as VTK XML unstructured grids (`.vtu`, one vertex cell per particle) and
//! ParaView time-series collections (`.pvd`). Files are written to a temporary name and renamed,
//! so a reader never sees a half-written file.

use crate::error::Result;
pub use crate::options::VtkFormat;
use crate::particles::Field;
use crate::sim::Sim;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use super::write_atomically;

/// The values of one `DataArray`, of the VTK type they are written as.
enum Values {
    Float64(Vec<f64>),
    Int64(Vec<i64>),
    UInt8(Vec<u8>),
}

impl Values {
    fn type_name(&self) -> &'static str {
        match self {
            Values::Float64(_) => "Float64",
            Values::Int64(_) => "Int64",
            Values::UInt8(_) => "UInt8",
        }
    }

    /// The values as text, `components` to a line.
    fn write_ascii(&self, out: &mut String, components: usize) {
        let mut put = |i: usize, v: &dyn std::fmt::Display| {
            let _ = write!(out, "{v}");
            out.push(if (i + 1).is_multiple_of(components) {
                '\n'
            } else {
                ' '
            });
        };
        match self {
            // `{:e}`: the shortest decimal that reads back to the same value.
            Values::Float64(v) => v
                .iter()
                .enumerate()
                .for_each(|(i, x)| put(i, &format_args!("{x:e}"))),
            Values::Int64(v) => v.iter().enumerate().for_each(|(i, x)| put(i, x)),
            Values::UInt8(v) => v.iter().enumerate().for_each(|(i, x)| put(i, x)),
        }
    }

    /// The appended block: the byte count as a little-endian `UInt64` (the file's
    /// `header_type`), then the values' little-endian bytes.
    fn write_raw(&self, out: &mut Vec<u8>) {
        let bytes = match self {
            Values::Float64(v) => 8 * v.len(),
            Values::Int64(v) => 8 * v.len(),
            Values::UInt8(v) => v.len(),
        };
        out.extend_from_slice(&(bytes as u64).to_le_bytes());
        match self {
            Values::Float64(v) => v
                .iter()
                .for_each(|x| out.extend_from_slice(&x.to_le_bytes())),
            Values::Int64(v) => v
                .iter()
                .for_each(|x| out.extend_from_slice(&x.to_le_bytes())),
            Values::UInt8(v) => out.extend_from_slice(v),
        }
    }
}

/// A named `DataArray` of `components` values per particle.
struct Array {
    name: &'static str,
    components: usize,
    values: Values,
}

/// Pads `D` components per particle to 3 (VTK vectors are 3D).
fn pad3(values: &[f64], d: usize) -> Vec<f64> {
    values
        .chunks_exact(d)
        .flat_map(move |c| (0..3).map(move |k| if k < d { c[k] } else { 0.0 }))
        .collect()
}

/// Pads `D×D` row-major tensors per particle to 3×3.
fn pad33(values: &[f64], d: usize) -> Vec<f64> {
    values
        .chunks_exact(d * d)
        .flat_map(move |c| {
            (0..9).map(move |k| {
                let (i, j) = (k / 3, k % 3);
                if i < d && j < d {
                    c[i * d + j]
                } else {
                    0.0
                }
            })
        })
        .collect()
}

/// The `.vtu` file of the particles of `sim`: points (one vertex cell each, in id order), and
/// point data `velocity`, `displacement`, `stress` (3×3, plane components zero-padded in 2D),
/// `pressure`, `volume`, `mass`, `plastic_strain` and `damage` (where a material has them,
/// [`Sim::carries`]), `material`. [`VtkFormat::Binary`] appends
/// the arrays as raw bytes after the XML, as ParaView writes them; [`VtkFormat::Ascii`] writes
/// them as text inside it.
pub fn particles_vtu<const D: usize>(sim: &Sim<D>, format: VtkFormat) -> Vec<u8> {
    let ps = &sim.particles;
    let n = ps.len();
    let float = |name, components, values| Array {
        name,
        components,
        values: Values::Float64(values),
    };
    let points = float("position", 3, pad3(&sim.field(Field::Position), D));
    let cells = [
        Array {
            name: "connectivity",
            components: 1,
            values: Values::Int64((0..n as i64).collect()),
        },
        Array {
            name: "offsets",
            components: 1,
            values: Values::Int64((1..=n as i64).collect()),
        },
        Array {
            name: "types",
            components: 1,
            values: Values::UInt8(vec![1; n]),
        },
    ];
    let mut data = vec![
        float("velocity", 3, pad3(&sim.field(Field::Velocity), D)),
        float("displacement", 3, pad3(&sim.field(Field::Displacement), D)),
        float("stress", 9, pad33(&sim.field(Field::Stress), D)),
    ];
    for f in [
        Field::Pressure,
        Field::Volume,
        Field::Mass,
        Field::PlasticStrain,
        Field::Damage,
    ] {
        // Plastic strain and damage where a material has them ([`Sim::carries`]).
        if sim.carries(f) {
            data.push(float(f.name(), 1, sim.field(f)));
        }
    }
    // In id order, as the fields above.
    data.push(float(
        "material",
        1,
        ps.slots().iter().map(|&p| ps.material[p] as f64).collect(),
    ));

    let mut xml = String::with_capacity(
        1024 + if format == VtkFormat::Ascii {
            200 * n
        } else {
            0
        },
    );
    xml.push_str("<?xml version=\"1.0\"?>\n<VTKFile type=\"UnstructuredGrid\" version=\"1.0\" byte_order=\"LittleEndian\" header_type=\"UInt64\">\n<UnstructuredGrid>\n");
    let _ = writeln!(
        xml,
        "<FieldData><DataArray type=\"Float64\" Name=\"TimeValue\" NumberOfTuples=\"1\" format=\"ascii\">{:e}</DataArray></FieldData>",
        sim.time()
    );
    let _ = writeln!(xml, "<Piece NumberOfPoints=\"{n}\" NumberOfCells=\"{n}\">");
    // Each array's element: in ASCII with its values, in binary with its offset into the
    // appended bytes (counted from the byte after the `_` that opens them).
    let mut appended = Vec::new();
    let mut element = |xml: &mut String, a: &Array| {
        let _ = write!(
            xml,
            "<DataArray type=\"{}\" Name=\"{}\" NumberOfComponents=\"{}\" ",
            a.values.type_name(),
            a.name,
            a.components
        );
        match format {
            VtkFormat::Ascii => {
                xml.push_str("format=\"ascii\">\n");
                a.values.write_ascii(xml, a.components);
                xml.push_str("</DataArray>\n");
            }
            VtkFormat::Binary => {
                let _ = writeln!(xml, "format=\"appended\" offset=\"{}\"/>", appended.len());
                a.values.write_raw(&mut appended);
            }
        }
    };
    xml.push_str("<Points>\n");
    element(&mut xml, &points);
    xml.push_str("</Points>\n<Cells>\n");
    for a in &cells {
        element(&mut xml, a);
    }
    xml.push_str("</Cells>\n<PointData Vectors=\"velocity\" Scalars=\"pressure\">\n");
    for a in &data {
        element(&mut xml, a);
    }
    xml.push_str("</PointData>\n</Piece>\n</UnstructuredGrid>\n");
    let mut out = xml.into_bytes();
    if format == VtkFormat::Binary {
        out.extend_from_slice(b"<AppendedData encoding=\"raw\">\n_");
        out.extend_from_slice(&appended);
        out.extend_from_slice(b"\n</AppendedData>\n");
    }
    out.extend_from_slice(b"</VTKFile>\n");
    out
}

/// Writes the particles of `sim` to one `.vtu` file ([`particles_vtu`]).
pub fn write_particles<const D: usize>(
    sim: &Sim<D>,
    path: impl AsRef<Path>,
    format: VtkFormat,
) -> Result<()> {
    write_atomically(path.as_ref(), &particles_vtu(sim, format))
}

/// A time series: frames `<prefix>_00000.vtu, …` and the collection `<prefix>.pvd` that lists
/// them with their times (open the `.pvd` in ParaView).
#[derive(Debug, Clone, PartialEq)]
pub struct VtkSeries {
    prefix: PathBuf,
    format: VtkFormat,
    frames: Vec<(f64, String)>,
}

impl VtkSeries {
    /// A series written in the default format ([`VtkFormat::Binary`]).
    pub fn new(prefix: impl Into<PathBuf>) -> Self {
        VtkSeries {
            prefix: prefix.into(),
            format: VtkFormat::default(),
            frames: Vec::new(),
        }
    }

    /// The format of the frames written from now on.
    pub fn set_format(&mut self, format: VtkFormat) {
        self.format = format;
    }

    pub fn prefix(&self) -> &Path {
        &self.prefix
    }

    pub fn frames(&self) -> usize {
        self.frames.len()
    }

    /// Writes the next frame and rewrites the collection file.
    pub fn write_frame<const D: usize>(&mut self, sim: &Sim<D>) -> Result<PathBuf> {
        let stem = self
            .prefix
            .file_name()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| "frame".into());
        let name = format!("{stem}_{:05}.vtu", self.frames.len());
        let path = self.prefix.with_file_name(&name);
        write_particles(sim, &path, self.format)?;
        self.frames.push((sim.time(), name));
        let mut pvd = String::from(
            "<?xml version=\"1.0\"?>\n<VTKFile type=\"Collection\" version=\"0.1\" byte_order=\"LittleEndian\">\n<Collection>\n",
        );
        for (t, file) in &self.frames {
            let _ = writeln!(
                pvd,
                "<DataSet timestep=\"{t:e}\" group=\"\" part=\"0\" file=\"{file}\"/>"
            );
        }
        pvd.push_str("</Collection>\n</VTKFile>\n");
        let mut pvd_path = self.prefix.clone().into_os_string();
        pvd_path.push(".pvd");
        write_atomically(Path::new(&pvd_path), pvd.as_bytes())?;
        Ok(path)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::material::Material;
    use crate::Vector;

    /// A small moving elastic body in 2D: 8 × 4 particles, sheared by their initial velocity.
    fn small_sim() -> Sim<2> {
        let mut sim = Sim::<2>::new([0.0, 0.0], [8, 8], 0.125).unwrap();
        let m = sim.add_material(Material::linear_elastic(1000.0, 1e6, 0.3).unwrap());
        let x: Vec<Vector<2>> = (0..32)
            .map(|k| Vector::<2>::new(0.3 + 0.05 * (k % 8) as f64, 0.4 + 0.05 * (k / 8) as f64))
            .collect();
        let v: Vec<Vector<2>> = x
            .iter()
            .map(|p| Vector::<2>::new(p[1] - 0.5, 0.1))
            .collect();
        sim.add_particles(m, &x, &[0.0025; 32], Some(&v)).unwrap();
        sim
    }

    /// The values of a named `DataArray` of a `.vtu` file, ASCII or appended raw (read by
    /// the format's rules, independently of the writer: the offset from the `_`, a `UInt64`
    /// byte count, little-endian values of the declared type).
    fn array(file: &[u8], name: &str) -> Vec<f64> {
        let split = file
            .windows(22)
            .position(|w| w == b"<AppendedData encoding")
            .unwrap_or(file.len());
        let text = std::str::from_utf8(&file[..split]).unwrap();
        let start = text.find(&format!("Name=\"{name}\"")).expect(name);
        let tag_start = text[..start].rfind('<').unwrap();
        let tag_end = start + text[start..].find('>').unwrap();
        let tag = &text[tag_start..tag_end];
        let attribute = |key: &str| {
            let k = tag.find(&format!("{key}=\"")).unwrap() + key.len() + 2;
            tag[k..k + tag[k..].find('"').unwrap()].to_string()
        };
        if attribute("format") == "ascii" {
            let body = &text[tag_end + 1..];
            let close = body.find("</DataArray>").unwrap();
            return body[..close]
                .split_whitespace()
                .map(|v| v.parse().unwrap())
                .collect();
        }
        assert_eq!(attribute("format"), "appended");
        let underscore = split + file[split..].iter().position(|&b| b == b'_').unwrap();
        let at = underscore + 1 + attribute("offset").parse::<usize>().unwrap();
        let bytes = u64::from_le_bytes(file[at..at + 8].try_into().unwrap()) as usize;
        let raw = &file[at + 8..at + 8 + bytes];
        match attribute("type").as_str() {
            "Float64" => raw
                .chunks_exact(8)
                .map(|c| f64::from_le_bytes(c.try_into().unwrap()))
                .collect(),
            "Int64" => raw
                .chunks_exact(8)
                .map(|c| i64::from_le_bytes(c.try_into().unwrap()) as f64)
                .collect(),
            "UInt8" => raw.iter().map(|&b| b as f64).collect(),
            t => panic!("type {t}"),
        }
    }

    #[test]
    fn series_writes_frames_and_collection_with_the_particle_data() {
        let dir = std::env::temp_dir().join(format!("rkmpm-vtk-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let mut sim = small_sim();
        let mut series = VtkSeries::new(dir.join("bar"));
        series.write_frame(&sim).unwrap();
        let dt = sim.stable_dt(0.2).unwrap();
        sim.step(dt).unwrap();
        // Storage out of id order, as the steps' sort leaves it in general.
        let reversed: Vec<u32> = (0..sim.particles.len() as u32).rev().collect();
        sim.particles
            .permute(&reversed, &mut crate::particles::SpareArrays::default());
        let second = series.write_frame(&sim).unwrap();
        assert_eq!(second, dir.join("bar_00001.vtu"));

        let pvd = std::fs::read_to_string(dir.join("bar.pvd")).unwrap();
        assert_eq!(pvd.matches("<DataSet ").count(), 2);
        assert!(pvd.contains("file=\"bar_00000.vtu\"") && pvd.contains("file=\"bar_00001.vtu\""));
        assert!(pvd.contains(&format!("timestep=\"{:e}\"", sim.time())));

        let vtu = std::fs::read(&second).unwrap();
        let n = sim.particles.len();
        let header = String::from_utf8_lossy(&vtu[..vtu.len().min(2000)]).into_owned();
        assert!(header.contains(&format!("NumberOfPoints=\"{n}\" NumberOfCells=\"{n}\"")));
        assert!(header.contains("format=\"appended\""), "binary by default");
        // Values round-trip exactly (raw bytes).
        let points = array(&vtu, "position");
        let velocity = array(&vtu, "velocity");
        let stress = array(&vtu, "stress");
        // The file lists the particles in id order, whatever their storage order.
        let ps = &sim.particles;
        let (mass, material) = (array(&vtu, "mass"), array(&vtu, "material"));
        for p in 0..n {
            let i = ps.id[p] as usize;
            assert_eq!(&points[3 * i..3 * i + 2], ps.position[p].as_slice());
            assert_eq!(points[3 * i + 2], 0.0);
            assert_eq!(&velocity[3 * i..3 * i + 2], ps.velocity[p].as_slice());
            assert_eq!(stress[9 * i], ps.stress[p][(0, 0)]);
            assert_eq!(stress[9 * i + 1], ps.stress[p][(0, 1)]);
            assert_eq!(stress[9 * i + 8], 0.0);
            assert_eq!(mass[i], ps.mass[p]);
            assert_eq!(material[i], ps.material[p] as f64);
        }
        assert_eq!(array(&vtu, "types").len(), n);
        assert_eq!(array(&vtu, "offsets").last().copied(), Some(n as f64));
        assert!(!dir.join("bar_00001.vtu.tmp").exists());
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// The ASCII file holds the binary one's arrays, value for value (`{:e}` prints the
    /// shortest decimal that reads back to the same `f64`), and is the larger.
    #[test]
    fn ascii_and_binary_files_hold_the_same_arrays() {
        let mut sim = small_sim();
        let dt = sim.stable_dt(0.2).unwrap();
        for _ in 0..3 {
            sim.step(dt).unwrap();
        }
        let binary = particles_vtu(&sim, VtkFormat::Binary);
        let ascii = particles_vtu(&sim, VtkFormat::Ascii);
        assert!(std::str::from_utf8(&ascii).is_ok());
        assert!(!String::from_utf8_lossy(&ascii).contains("AppendedData"));
        let names = [
            "position",
            "connectivity",
            "offsets",
            "types",
            "velocity",
            "displacement",
            "stress",
            "pressure",
            "volume",
            "mass",
            "material",
        ];
        // An elastic material has neither plastic strain nor damage: not written.
        for name in ["plastic_strain", "damage"] {
            let text = String::from_utf8_lossy(&ascii).into_owned();
            assert!(!text.contains(&format!("Name=\"{name}\"")), "{name}");
        }
        let n = sim.particles.len();
        for name in names {
            let (b, a) = (array(&binary, name), array(&ascii, name));
            assert_eq!(b.len(), a.len(), "{name}");
            assert!(b.len() >= n, "{name}");
            for (x, y) in b.iter().zip(&a) {
                assert_eq!(x.to_bits(), y.to_bits(), "{name}");
            }
        }
        assert_eq!(array(&binary, "stress")[9 * 3..9 * 3 + 2], {
            let ps = &sim.particles;
            let p = ps.slots()[3];
            [ps.stress[p][(0, 0)], ps.stress[p][(0, 1)]]
        });
        assert!(
            binary.len() < ascii.len(),
            "{} {}",
            binary.len(),
            ascii.len()
        );
    }

    /// A Johnson–Cook material with damage puts `plastic_strain` and `damage` into the file, in
    /// id order, as `Sim::field` gives them; without damage only `plastic_strain`.
    #[test]
    fn plastic_strain_and_damage_are_written_where_a_material_has_them() {
        for damage in [true, false] {
            let mut sim = Sim::<2>::new([0.0, 0.0], [8, 8], 0.125).unwrap();
            let mut p = crate::material::ofhc_copper();
            if !damage {
                p.damage = None;
            }
            let m = sim.add_material(Material::johnson_cook(p).unwrap());
            let x: Vec<Vector<2>> = (0..16)
                .map(|k| Vector::<2>::new(0.3 + 0.05 * (k % 4) as f64, 0.4 + 0.05 * (k / 4) as f64))
                .collect();
            sim.add_particles(m, &x, &[0.0025; 16], None).unwrap();
            let text = particles_vtu(&sim, VtkFormat::Ascii);
            let has =
                |name: &str| String::from_utf8_lossy(&text).contains(&format!("Name=\"{name}\""));
            assert!(has("plastic_strain"));
            assert_eq!(has("damage"), damage);
            if damage {
                assert_eq!(array(&text, "damage"), sim.field(Field::Damage));
            }
        }
    }

    /// A write into a directory that does not exist says which file it could not write.
    #[test]
    fn a_write_into_a_missing_directory_names_the_path() {
        let sim = small_sim();
        let path = std::env::temp_dir().join("rkmpm-no-such-dir/bar.vtu");
        let e = write_particles(&sim, &path, VtkFormat::Binary).unwrap_err();
        assert_eq!(e.kind, crate::error::ErrorKind::Io);
        assert!(
            e.message
                .starts_with(&format!("writing {}: ", path.display())),
            "{e}"
        );
    }
}
