//! Particle output as VTK XML unstructured grids (`.vtu`, one vertex cell per particle) and
//! ParaView time-series collections (`.pvd`). Files are written to a temporary name and renamed,
//! so a reader never sees a half-written file.

use crate::error::Result;
use crate::particles::Field;
use crate::sim::Sim;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use super::write_atomically;

fn data_array(out: &mut String, name: &str, components: usize, values: impl Iterator<Item = f64>) {
    let _ = writeln!(
        out,
        "<DataArray type=\"Float64\" Name=\"{name}\" NumberOfComponents=\"{components}\" format=\"ascii\">"
    );
    for (i, v) in values.enumerate() {
        let _ = write!(out, "{v:e}");
        out.push(if (i + 1) % components == 0 { '\n' } else { ' ' });
    }
    out.push_str("</DataArray>\n");
}

/// Pads `D` components per particle to 3 (VTK vectors are 3D).
fn pad3(values: &[f64], d: usize) -> impl Iterator<Item = f64> + '_ {
    values
        .chunks_exact(d)
        .flat_map(move |c| (0..3).map(move |k| if k < d { c[k] } else { 0.0 }))
}

/// Pads `D×D` row-major tensors per particle to 3×3.
fn pad33(values: &[f64], d: usize) -> impl Iterator<Item = f64> + '_ {
    values.chunks_exact(d * d).flat_map(move |c| {
        (0..9).map(move |k| {
            let (i, j) = (k / 3, k % 3);
            if i < d && j < d {
                c[i * d + j]
            } else {
                0.0
            }
        })
    })
}

/// The `.vtu` text of the particles of `sim`: points, and point data `velocity`, `displacement`,
/// `stress` (3×3, plane components zero-padded in 2D), `pressure`, `volume`, `mass`, `material`.
pub fn particles_vtu<const D: usize>(sim: &Sim<D>) -> String {
    let ps = sim.particles();
    let n = ps.len();
    let mut s = String::with_capacity(200 * n + 1024);
    s.push_str("<?xml version=\"1.0\"?>\n<VTKFile type=\"UnstructuredGrid\" version=\"1.0\" byte_order=\"LittleEndian\" header_type=\"UInt64\">\n<UnstructuredGrid>\n");
    let _ = writeln!(
        s,
        "<FieldData><DataArray type=\"Float64\" Name=\"TimeValue\" NumberOfTuples=\"1\" format=\"ascii\">{:e}</DataArray></FieldData>",
        sim.time()
    );
    let _ = writeln!(s, "<Piece NumberOfPoints=\"{n}\" NumberOfCells=\"{n}\">");
    s.push_str("<Points>\n");
    data_array(&mut s, "position", 3, pad3(&sim.field(Field::Position), D));
    s.push_str(
        "</Points>\n<Cells>\n<DataArray type=\"Int64\" Name=\"connectivity\" format=\"ascii\">\n",
    );
    for p in 0..n {
        let _ = write!(s, "{p} ");
    }
    s.push_str("\n</DataArray>\n<DataArray type=\"Int64\" Name=\"offsets\" format=\"ascii\">\n");
    for p in 0..n {
        let _ = write!(s, "{} ", p + 1);
    }
    s.push_str("\n</DataArray>\n<DataArray type=\"UInt8\" Name=\"types\" format=\"ascii\">\n");
    s.push_str(&"1 ".repeat(n));
    s.push_str("\n</DataArray>\n</Cells>\n<PointData Vectors=\"velocity\" Scalars=\"pressure\">\n");
    data_array(&mut s, "velocity", 3, pad3(&sim.field(Field::Velocity), D));
    data_array(
        &mut s,
        "displacement",
        3,
        pad3(&sim.field(Field::Displacement), D),
    );
    data_array(&mut s, "stress", 9, pad33(&sim.field(Field::Stress), D));
    for f in [
        Field::Pressure,
        Field::Volume,
        Field::Mass,
        Field::PlasticStrain,
    ] {
        data_array(&mut s, f.name(), 1, sim.field(f).into_iter());
    }
    // In id order, as the fields above.
    let slots = ps.slots();
    data_array(
        &mut s,
        "material",
        1,
        slots.iter().map(|&p| ps.material[p] as f64),
    );
    s.push_str("</PointData>\n</Piece>\n</UnstructuredGrid>\n</VTKFile>\n");
    s
}

/// Writes the particles of `sim` to one `.vtu` file.
pub fn write_particles<const D: usize>(sim: &Sim<D>, path: impl AsRef<Path>) -> Result<()> {
    write_atomically(path.as_ref(), particles_vtu(sim).as_bytes())
}

/// A time series: frames `<prefix>_00000.vtu, …` and the collection `<prefix>.pvd` that lists
/// them with their times (open the `.pvd` in ParaView).
#[derive(Debug, Clone, PartialEq)]
pub struct VtkSeries {
    prefix: PathBuf,
    frames: Vec<(f64, String)>,
}

impl VtkSeries {
    pub fn new(prefix: impl Into<PathBuf>) -> Self {
        VtkSeries {
            prefix: prefix.into(),
            frames: Vec::new(),
        }
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
        write_particles(sim, &path)?;
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

    /// The numbers in a named `DataArray` of a `.vtu` text.
    fn array(text: &str, name: &str) -> Vec<f64> {
        let start = text.find(&format!("Name=\"{name}\"")).expect(name);
        let body = &text[start..];
        let open = body.find('>').unwrap() + 1;
        let close = body.find("</DataArray>").unwrap();
        body[open..close]
            .split_whitespace()
            .map(|v| v.parse().unwrap())
            .collect()
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
        let reversed: Vec<u32> = (0..sim.particles().len() as u32).rev().collect();
        sim.particles
            .permute(&reversed, &mut crate::particles::SpareArrays::default());
        let second = series.write_frame(&sim).unwrap();
        assert_eq!(second, dir.join("bar_00001.vtu"));

        let pvd = std::fs::read_to_string(dir.join("bar.pvd")).unwrap();
        assert_eq!(pvd.matches("<DataSet ").count(), 2);
        assert!(pvd.contains("file=\"bar_00000.vtu\"") && pvd.contains("file=\"bar_00001.vtu\""));
        assert!(pvd.contains(&format!("timestep=\"{:e}\"", sim.time())));

        let vtu = std::fs::read_to_string(&second).unwrap();
        let n = sim.particles().len();
        assert!(vtu.contains(&format!("NumberOfPoints=\"{n}\" NumberOfCells=\"{n}\"")));
        // Values round-trip exactly: `{:e}` prints the shortest representation that parses back.
        let points = array(&vtu, "position");
        let velocity = array(&vtu, "velocity");
        let stress = array(&vtu, "stress");
        // The file lists the particles in id order, whatever their storage order.
        let ps = sim.particles();
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

    /// A write into a directory that does not exist says which file it could not write.
    #[test]
    fn a_write_into_a_missing_directory_names_the_path() {
        let sim = small_sim();
        let path = std::env::temp_dir().join("rkmpm-no-such-dir/bar.vtu");
        let e = write_particles(&sim, &path).unwrap_err();
        assert_eq!(e.kind, crate::error::ErrorKind::Io);
        assert!(
            e.message
                .starts_with(&format!("writing {}: ", path.display())),
            "{e}"
        );
    }
}
