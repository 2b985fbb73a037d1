//! Checkpoint and restart: the whole state of a simulation in one versioned, checksummed binary
//! file, so that a run stopped, saved, loaded and continued gives the same particle data bit for
//! bit as the uninterrupted run.
//!
//! Layout (little-endian): the magic `RKMPMCHK`, the format version (`u32`), the dimension
//! (`u32`), the payload length (`u64`), the payload, and the CRC-32 of the payload (`u32`). The
//! payload holds the grid, the options, the materials (every stored field, derived constants
//! included, so nothing is recomputed differently), the particles in their storage order with
//! their ids (the order fixes the order of the node sums), the boundary points, the time and the
//! step count. It does not hold the body-force callback (set it again after loading) or
//! any scratch space (every step rebuilds it).
//!
//! Files are written to a temporary name and renamed: an existing checkpoint is replaced only by
//! a complete new one. A file that is truncated, has another magic, or fails its checksum is
//! refused with `CorruptFile`; a newer format version with `Unsupported`. Files of version 1
//! (without ids) still load.

use crate::error::{Error, ErrorKind, Result};
use crate::integration::BoundaryPoints;
use crate::material::{
    Constitutive, DruckerPrager, ElasticConstants, History, InertialRheology, JohnsonCook,
    JohnsonCookParameters, LinearElastic, Material, MieGruneisen, NeoHookean, Rigid,
};
use crate::options::{
    Contact, Integration, IntegrationKind, Scheme, Shape, ShapeKind, Transfer, TransferKind, Wall,
    Walls,
};
use crate::particles::Particles;
use crate::sim::Sim;
use crate::{Matrix, Vector};
use nalgebra::Matrix3;
use std::path::Path;

const MAGIC: &[u8; 8] = b"RKMPMCHK";
/// Format version written by this build. Version 2 adds the particles' ids (their storage is
/// sorted by grid block); version 1 files, written before, load with the particles in id order.
/// Version 3 adds the energy ledger (`Sim::set_energy_accounting`) after the step count;
/// older files load with the accounting off. Version 4 adds the VC solve's stopping rule
/// (`Sim::set_vc_solve`) at the end; older files, written when the exact solve was the default,
/// load with `VcSolve::EXACT`. Version 5 writes the automatic rule (`VcSolve::automatic`, no
/// rule given) as a tolerance and an iteration bound of zero; version 4 files load with the
/// rule they hold.
/// Version 6 adds the found surface's refresh interval (`Sim::set_vc_surface_refresh`), its
/// age and the surface as carried, for an exact restart; older files load with the default
/// interval and find the surface anew at their first step.
/// Version 7 adds the VC solve's interval (`VcSolve::interval`; zero with the automatic rule)
/// and the coefficients carried by node between solves with their age, for an exact restart;
/// older files load with a given rule solving at every step, as they ran, and solve at their
/// first step.
/// Version 8 adds the solve before the carried one (the steps between them, its nodes and
/// values), along whose line the carried coefficients go on; version 7 files load without it
/// (held constant until the next two solves).
pub const CHECKPOINT_VERSION: u32 = 8;

/// Writes boundary points: positions, reference and current area normals, deformation
/// gradients and tractions.
fn write_points<const D: usize>(w: &mut Writer, b: &BoundaryPoints<D>) {
    w.vectors(&b.position);
    w.vectors(&b.reference_area_normal);
    w.vectors(&b.area_normal);
    w.matrices(&b.deformation_gradient);
    w.vectors(&b.traction);
}

/// Reads what [`write_points`] wrote: arrays of one length (tractions may be empty), points
/// inside the grid.
fn read_points<const D: usize>(
    r: &mut Reader,
    grid: &crate::grid::Grid<D>,
    what: &str,
) -> Result<BoundaryPoints<D>> {
    let b = BoundaryPoints {
        position: r.vectors()?,
        reference_area_normal: r.vectors()?,
        area_normal: r.vectors()?,
        deformation_gradient: r.matrices()?,
        traction: r.vectors()?,
    };
    let nb = b.position.len();
    if [
        b.reference_area_normal.len(),
        b.area_normal.len(),
        b.deformation_gradient.len(),
    ]
    .iter()
    .any(|&k| k != nb)
        || !(b.traction.is_empty() || b.traction.len() == nb)
    {
        return Err(corrupt(format!("the {what} arrays differ in length")));
    }
    if let Some(k) = b.position.iter().position(|x| !grid.contains(x)) {
        return Err(corrupt(format!("{what} {k} lies outside the grid")));
    }
    Ok(b)
}

fn corrupt(what: impl Into<String>) -> Error {
    Error::new(ErrorKind::CorruptFile, what)
}

/// Little-endian writer of the payload.
#[derive(Default)]
struct Writer(Vec<u8>);

impl Writer {
    fn u32(&mut self, v: u32) {
        self.0.extend_from_slice(&v.to_le_bytes());
    }
    fn u64(&mut self, v: u64) {
        self.0.extend_from_slice(&v.to_le_bytes());
    }
    fn f64(&mut self, v: f64) {
        self.0.extend_from_slice(&v.to_le_bytes());
    }
    fn f64s<'a>(&mut self, v: impl IntoIterator<Item = &'a f64>) {
        for x in v {
            self.f64(*x);
        }
    }
    fn len(&mut self, n: usize) {
        self.u64(n as u64);
    }
    fn vectors<const D: usize>(&mut self, v: &[Vector<D>]) {
        self.len(v.len());
        v.iter().for_each(|x| self.f64s(x.iter()));
    }
    fn matrices<const D: usize>(&mut self, v: &[Matrix<D>]) {
        self.len(v.len());
        v.iter().for_each(|x| self.f64s(x.iter()));
    }
    fn scalars(&mut self, v: &[f64]) {
        self.len(v.len());
        self.f64s(v);
    }
}

/// Reader of the payload; every read fails cleanly at the end of the data.
struct Reader<'a>(&'a [u8]);

impl Reader<'_> {
    fn take(&mut self, n: usize) -> Result<&[u8]> {
        if self.0.len() < n {
            return Err(corrupt("the checkpoint ends early"));
        }
        let (head, tail) = self.0.split_at(n);
        self.0 = tail;
        Ok(head)
    }
    fn u32(&mut self) -> Result<u32> {
        Ok(u32::from_le_bytes(
            self.take(4)?.try_into().expect("4 bytes"),
        ))
    }
    fn u64(&mut self) -> Result<u64> {
        Ok(u64::from_le_bytes(
            self.take(8)?.try_into().expect("8 bytes"),
        ))
    }
    fn f64(&mut self) -> Result<f64> {
        Ok(f64::from_le_bytes(
            self.take(8)?.try_into().expect("8 bytes"),
        ))
    }
    /// A length, refused when the remaining data cannot hold `n` items of `item` bytes.
    fn len(&mut self, item: usize) -> Result<usize> {
        let n = self.u64()?;
        if n > (self.0.len() / item.max(1)) as u64 {
            return Err(corrupt(format!("a stored length ({n}) exceeds the file")));
        }
        Ok(n as usize)
    }
    fn vectors<const D: usize>(&mut self) -> Result<Vec<Vector<D>>> {
        let n = self.len(8 * D)?;
        (0..n)
            .map(|_| {
                let mut v = Vector::<D>::zeros();
                for c in v.iter_mut() {
                    *c = self.f64()?;
                }
                Ok(v)
            })
            .collect()
    }
    fn matrices<const D: usize>(&mut self) -> Result<Vec<Matrix<D>>> {
        let n = self.len(8 * D * D)?;
        (0..n)
            .map(|_| {
                let mut m = Matrix::<D>::zeros();
                for c in m.iter_mut() {
                    *c = self.f64()?;
                }
                Ok(m)
            })
            .collect()
    }
    fn scalars(&mut self) -> Result<Vec<f64>> {
        let n = self.len(8)?;
        (0..n).map(|_| self.f64()).collect()
    }
}

fn write_elastic(w: &mut Writer, e: &ElasticConstants) {
    w.f64s(&[e.density, e.young, e.poisson, e.lambda, e.mu]);
}

fn read_elastic(r: &mut Reader) -> Result<ElasticConstants> {
    Ok(ElasticConstants {
        density: r.f64()?,
        young: r.f64()?,
        poisson: r.f64()?,
        lambda: r.f64()?,
        mu: r.f64()?,
    })
}

fn write_material(w: &mut Writer, m: &Material) {
    match m {
        Material::LinearElastic(LinearElastic(e)) => {
            w.u32(0);
            write_elastic(w, e);
        }
        Material::NeoHookean(NeoHookean(e)) => {
            w.u32(1);
            write_elastic(w, e);
        }
        Material::DruckerPrager(dp) => {
            // Tag 2: rate-independent (the yield surface's constants only, as format 1 always
            // wrote them); tag 5: with the μ(I) rheology's three after them.
            let c = dp.stored_constants();
            let n = if dp.rheology.is_some() {
                w.u32(5);
                DruckerPrager::STORED
            } else {
                w.u32(2);
                DruckerPrager::STORED_YIELD
            };
            write_elastic(w, &dp.elastic);
            w.f64s(&c[..n]);
        }
        Material::JohnsonCook(jc) => {
            w.u32(3);
            write_elastic(w, &jc.elastic);
            let p = &jc.p;
            w.f64s(&[
                p.density,
                p.young,
                p.poisson,
                p.a,
                p.b,
                p.n,
                p.c,
                p.reference_strain_rate,
                p.m,
                p.room_temperature,
                p.melt_temperature,
                p.specific_heat,
                p.taylor_quinney,
            ]);
            w.u32(u32::from(p.damage.is_some()));
            w.f64s(&p.damage.unwrap_or_default());
            let eos = p
                .eos
                .map_or([0.0; 3], |e| [e.sound_speed, e.slope, e.gamma0]);
            w.u32(u32::from(p.eos.is_some()));
            w.f64s(&eos);
        }
        Material::Rigid(rigid) => {
            w.u32(4);
            w.f64(rigid.density);
            w.f64s(&rigid.velocity);
        }
    }
}

fn read_material(r: &mut Reader) -> Result<Material> {
    let tag = r.u32()?;
    let read_n =
        |n: usize, r: &mut Reader| -> Result<Vec<f64>> { (0..n).map(|_| r.f64()).collect() };
    Ok(match tag {
        0 => Material::LinearElastic(LinearElastic(read_elastic(r)?)),
        1 => Material::NeoHookean(NeoHookean(read_elastic(r)?)),
        2 | 5 => {
            let e = read_elastic(r)?;
            let stored = if tag == 5 {
                DruckerPrager::STORED
            } else {
                DruckerPrager::STORED_YIELD
            };
            let mut c = read_n(stored, r)?;
            c.resize(DruckerPrager::STORED, 0.0);
            if tag == 5 {
                InertialRheology::new(c[6], c[7], c[8])
                    .map_err(|e| corrupt(format!("a μ(I) rheology with {}", e.message)))?;
            }
            Material::DruckerPrager(DruckerPrager::from_stored(e, &c))
        }
        3 => {
            let elastic = read_elastic(r)?;
            let v = read_n(13, r)?;
            let damage_on = r.u32()?;
            let d = read_n(5, r)?;
            let eos_on = r.u32()?;
            let e = read_n(3, r)?;
            Material::JohnsonCook(JohnsonCook {
                elastic,
                p: JohnsonCookParameters {
                    density: v[0],
                    young: v[1],
                    poisson: v[2],
                    a: v[3],
                    b: v[4],
                    n: v[5],
                    c: v[6],
                    reference_strain_rate: v[7],
                    m: v[8],
                    room_temperature: v[9],
                    melt_temperature: v[10],
                    specific_heat: v[11],
                    taylor_quinney: v[12],
                    damage: (damage_on == 1).then(|| [d[0], d[1], d[2], d[3], d[4]]),
                    eos: (eos_on == 1).then_some(MieGruneisen {
                        sound_speed: e[0],
                        slope: e[1],
                        gamma0: e[2],
                    }),
                },
            })
        }
        4 => {
            let density = r.f64()?;
            let v = read_n(3, r)?;
            Material::Rigid(Rigid {
                density,
                velocity: [v[0], v[1], v[2]],
            })
        }
        other => return Err(corrupt(format!("unknown material tag {other}"))),
    })
}

fn write_options<const D: usize>(w: &mut Writer, sim: &Sim<D>) {
    let o = &sim.options;
    // Each option is its kind's code followed by the parameters that kind carries.
    w.u32(o.shape.kind().into());
    if let Shape::Rk { order, support } = o.shape {
        w.u32(order);
        w.f64(support);
    }
    w.u32(o.integration.kind().into());
    if let Integration::Vc { order } = o.integration {
        w.u32(order);
    }
    w.u32(o.transfer.kind().into());
    if let Transfer::PicFlip { flip } = o.transfer {
        w.f64(flip);
    }
    w.u32(o.scheme.into());
    w.f64s(o.gravity.iter());
    for face in o.walls.faces.iter().flatten() {
        w.u32(face.kind().into());
        w.f64(face.friction());
    }
    w.u32(u32::from(o.contact.is_some()));
    w.f64(o.contact.map_or(0.0, |c| c.friction));
}

/// The option kind `K` of `code`, or a corrupt-file error naming `what`.
fn kind<K: TryFrom<u32>>(what: &str, code: u32) -> Result<K> {
    K::try_from(code).map_err(|_| corrupt(format!("unknown {what} tag {code}")))
}

fn read_options<const D: usize>(r: &mut Reader, sim: &mut Sim<D>) -> Result<()> {
    let shape = match kind("shape", r.u32()?)? {
        ShapeKind::Rk => Shape::Rk {
            order: r.u32()?,
            support: r.f64()?,
        },
        other => Shape::from_kind(other, 0, 0.0),
    };
    let integration = match kind("integration", r.u32()?)? {
        IntegrationKind::Vc => Integration::Vc { order: r.u32()? },
        other => Integration::from_kind(other, 0),
    };
    let transfer = match kind("transfer", r.u32()?)? {
        TransferKind::PicFlip => Transfer::PicFlip { flip: r.f64()? },
        other => Transfer::from_kind(other, 0.0),
    };
    let scheme: Scheme = kind("scheme", r.u32()?)?;
    let mut gravity = Vector::<D>::zeros();
    for g in gravity.iter_mut() {
        *g = r.f64()?;
    }
    let mut walls = Walls::<D>::default();
    for face in walls.faces.iter_mut().flatten() {
        let (tag, mu) = (r.u32()?, r.f64()?);
        *face = Wall::from_kind(kind("wall", tag)?, mu);
    }
    let contact_on = r.u32()?;
    let friction = r.f64()?;
    // The setters validate what they get, so a damaged file cannot smuggle in bad options.
    sim.set_shape(shape)?;
    sim.set_integration(integration)?;
    sim.set_transfer(transfer)?;
    sim.set_scheme(scheme)?;
    sim.set_gravity(gravity)?;
    for a in 0..D {
        for s in [crate::walls::Side::Low, crate::walls::Side::High] {
            sim.set_wall(a, s, walls.faces[a][s as usize])?;
        }
    }
    sim.options.contact = (contact_on == 1).then_some(Contact { friction });
    Ok(())
}

fn write_particles<const D: usize>(w: &mut Writer, ps: &Particles<D>, version: u32) {
    w.vectors(&ps.position);
    w.vectors(&ps.reference_position);
    w.vectors(&ps.velocity);
    w.matrices(&ps.deformation_gradient);
    w.scalars(&ps.reference_volume);
    w.scalars(&ps.mass);
    w.matrices(&ps.stress);
    w.scalars(&ps.pressure);
    w.len(ps.material.len());
    ps.material.iter().for_each(|&m| w.u32(m));
    w.matrices(&ps.affine);
    w.len(ps.history.len());
    for s in &ps.history {
        w.f64s(s.elastic_deformation.iter());
        w.f64s(&[s.plastic_strain, s.damage, s.heating]);
    }
    if version >= 2 {
        w.len(ps.id.len());
        ps.id.iter().for_each(|&i| w.u32(i));
    }
}

fn read_particles<const D: usize>(r: &mut Reader, version: u32) -> Result<Particles<D>> {
    let mut ps = Particles::<D> {
        position: r.vectors()?,
        reference_position: r.vectors()?,
        velocity: r.vectors()?,
        deformation_gradient: r.matrices()?,
        reference_volume: r.scalars()?,
        mass: r.scalars()?,
        stress: r.matrices()?,
        pressure: r.scalars()?,
        ..Default::default()
    };
    let n = r.len(4)?;
    ps.material = (0..n).map(|_| r.u32()).collect::<Result<_>>()?;
    ps.affine = r.matrices()?;
    let n = r.len(8 * 12)?;
    ps.history = (0..n)
        .map(|_| {
            let mut fe = Matrix3::zeros();
            for c in fe.iter_mut() {
                *c = r.f64()?;
            }
            Ok(History {
                elastic_deformation: fe,
                plastic_strain: r.f64()?,
                damage: r.f64()?,
                heating: r.f64()?,
            })
        })
        .collect::<Result<_>>()?;
    let len = ps.position.len();
    if version >= 2 {
        let n = r.len(4)?;
        ps.id = (0..n).map(|_| r.u32()).collect::<Result<_>>()?;
        // A permutation of 0..len: every id once.
        let mut seen = vec![false; len];
        if n != len
            || !ps
                .id
                .iter()
                .all(|&i| (i as usize) < len && !std::mem::replace(&mut seen[i as usize], true))
        {
            return Err(corrupt("the particle ids are not a permutation"));
        }
    } else {
        ps.id = (0..len as u32).collect();
    }
    let same = [
        ps.reference_position.len(),
        ps.velocity.len(),
        ps.deformation_gradient.len(),
        ps.reference_volume.len(),
        ps.mass.len(),
        ps.stress.len(),
        ps.pressure.len(),
        ps.material.len(),
    ]
    .iter()
    .all(|&k| k == len);
    let optional = |k: usize| k == 0 || k == len;
    if !same || !optional(ps.affine.len()) || !optional(ps.history.len()) {
        return Err(corrupt("the particle arrays differ in length"));
    }
    Ok(ps)
}

impl<const D: usize> Sim<D> {
    /// The checkpoint of this simulation as bytes (see the module documentation).
    pub fn checkpoint_bytes(&self) -> Vec<u8> {
        self.encode(CHECKPOINT_VERSION)
    }

    /// The checkpoint in format `version` (1 to 4; tests write older versions to read them
    /// back).
    fn encode(&self, version: u32) -> Vec<u8> {
        let mut w = Writer::default();
        w.f64s(self.grid.origin.iter());
        self.grid.cells.iter().for_each(|&c| w.u64(c as u64));
        w.f64(self.grid.cell_size);
        write_options(&mut w, self);
        w.len(self.materials.len());
        self.materials
            .iter()
            .for_each(|m| write_material(&mut w, m));
        write_particles(&mut w, &self.particles, version);
        write_points(&mut w, &self.boundary);
        w.f64(self.time);
        w.u64(self.steps);
        if version >= 3 {
            let e = &self.energy;
            w.u32(u32::from(e.on));
            w.f64s(
                [
                    e.start,
                    e.stored_start,
                    e.stress_work,
                    e.external_work,
                    e.friction,
                    e.contact,
                ]
                .iter(),
            );
        }
        if version >= 5 && self.vc_solve_is_automatic() {
            w.f64(0.0);
            w.u64(0);
        } else if version >= 4 {
            w.f64(self.vc_solve().tolerance);
            w.u64(self.vc_solve().max_iterations as u64);
        }
        if version >= 6 {
            w.u32(self.vc_surface_refresh);
            w.u32(self.surface_age);
            write_points(&mut w, &self.surface);
        }
        if version >= 7 {
            w.u32(match self.vc_solve_is_automatic() {
                true => 0,
                false => self.vc_solve().interval,
            });
            let carried = self.vc.as_ref().map(|vc| vc.carried());
            w.u32(carried.map_or(0, |c| c.age));
            w.len(carried.map_or(0, |c| c.per()));
            w.len(carried.map_or(0, |c| c.entries().count()));
            for (n, v) in carried.iter().flat_map(|c| c.entries()) {
                w.u64(n as u64);
                w.f64s(v);
            }
            if version >= 8 {
                w.u32(carried.map_or(0, |c| c.span()));
                w.len(carried.map_or(0, |c| c.entries_before().count()));
                for (n, v) in carried.iter().flat_map(|c| c.entries_before()) {
                    w.u64(n as u64);
                    w.f64s(v);
                }
            }
        }
        let payload = w.0;
        let mut out = Vec::with_capacity(payload.len() + 28);
        out.extend_from_slice(MAGIC);
        out.extend_from_slice(&version.to_le_bytes());
        out.extend_from_slice(&(D as u32).to_le_bytes());
        out.extend_from_slice(&(payload.len() as u64).to_le_bytes());
        out.extend_from_slice(&payload);
        out.extend_from_slice(&crc32fast::hash(&payload).to_le_bytes());
        out
    }

    /// Saves the checkpoint to `path`, atomically (temporary file, then rename).
    pub fn save(&self, path: impl AsRef<Path>) -> Result<()> {
        super::write_atomically(path.as_ref(), &self.checkpoint_bytes())
    }

    /// Restores a simulation from checkpoint bytes. The body-force callback is not part of a
    /// checkpoint: set it again.
    pub fn from_checkpoint_bytes(bytes: &[u8]) -> Result<Self> {
        let (version, dim) = checkpoint_frame(bytes)?;
        if dim != D {
            return Err(Error::invalid(format!(
                "the checkpoint is of a {dim}D simulation, not {D}D"
            )));
        }
        let payload = &bytes[24..bytes.len() - 4];
        // The frame is intact (checksum), so a value the engine refuses means a damaged or forged
        // file: every refusal below is `CorruptFile`.
        Self::decode(payload, version).map_err(|e| match e.kind {
            ErrorKind::CorruptFile => e,
            _ => corrupt(format!(
                "the checkpoint holds a value the engine refuses: {}",
                e.message
            )),
        })
    }

    fn decode(payload: &[u8], version: u32) -> Result<Self> {
        let mut r = Reader(payload);
        let mut origin = Vector::<D>::zeros();
        for c in origin.iter_mut() {
            *c = r.f64()?;
        }
        let mut cells = [0usize; D];
        for c in cells.iter_mut() {
            *c = usize::try_from(r.u64()?).map_err(|_| corrupt("cell count too large"))?;
        }
        let cell_size = r.f64()?;
        let mut sim = Sim::<D>::new(origin, cells, cell_size)?;
        read_options(&mut r, &mut sim)?;
        let n = r.len(4)?;
        sim.materials = (0..n)
            .map(|_| read_material(&mut r))
            .collect::<Result<_>>()?;
        let ps = read_particles::<D>(&mut r, version)?;
        if let Some(p) = ps
            .material
            .iter()
            .position(|&m| m as usize >= sim.materials.len())
        {
            return Err(corrupt(format!(
                "particle {p} refers to a missing material"
            )));
        }
        if let Some(p) = ps.position.iter().position(|x| !sim.grid.contains(x)) {
            return Err(corrupt(format!("particle {p} lies outside the grid")));
        }
        let n = ps.len();
        let apic = sim.options.transfer.is_affine();
        if ps.affine.len() != if apic { n } else { 0 } {
            return Err(corrupt(format!(
                "{} affine matrices for {n} particles under {:?}",
                ps.affine.len(),
                sim.options.transfer
            )));
        }
        let history = ps
            .material
            .iter()
            .any(|&m| !sim.materials[m as usize].is_elastic());
        if history && ps.history.len() != n {
            return Err(corrupt(format!(
                "{} history records for {n} particles of a plastic material",
                ps.history.len()
            )));
        }
        sim.particles = ps;
        sim.boundary = read_points(&mut r, &sim.grid, "boundary point")?;
        sim.time = r.f64()?;
        sim.steps = r.u64()?;
        if version >= 3 {
            let on = match r.u32()? {
                0 => false,
                1 => true,
                k => return Err(corrupt(format!("energy accounting flag {k}"))),
            };
            sim.energy = crate::energy::EnergyLedger {
                on,
                start: r.f64()?,
                stored_start: r.f64()?,
                stress_work: r.f64()?,
                external_work: r.f64()?,
                friction: r.f64()?,
                contact: r.f64()?,
            };
        }
        let solve = if version >= 4 {
            crate::VcSolve {
                tolerance: r.f64()?,
                max_iterations: usize::try_from(r.u64()?)
                    .map_err(|_| corrupt("VC solve iteration count too large"))?,
                interval: 1,
            }
        } else {
            crate::VcSolve::EXACT
        };
        if version >= 5 && solve.tolerance == 0.0 && solve.max_iterations == 0 {
            sim.set_vc_solve_automatic();
        } else {
            sim.set_vc_solve(solve)?;
        }
        if version >= 6 {
            sim.set_vc_surface_refresh(r.u32()?)
                .map_err(|_| corrupt("a found-surface refresh of zero steps"))?;
            sim.surface_age = r.u32()?;
            sim.surface = read_points(&mut r, &sim.grid, "found surface point")?;
        }
        if version >= 7 {
            let interval = r.u32()?;
            if !sim.vc_solve_is_automatic() {
                let solve = crate::VcSolve {
                    interval,
                    ..sim.vc_solve()
                };
                sim.set_vc_solve(solve)
                    .map_err(|_| corrupt("a VC solve interval of zero steps"))?;
            }
            let age = r.u32()?;
            let per = r.len(8)?;
            let node_count = sim.grid.node_count();
            // A solve's nodes and values, `per` a node.
            let read_solve = |r: &mut Reader| -> Result<(Vec<usize>, Vec<f64>)> {
                let count = r.len(8 * (per + 1))?;
                let (mut nodes, mut values) =
                    (Vec::with_capacity(count), Vec::with_capacity(count * per));
                for _ in 0..count {
                    let n = r.u64()?;
                    if n >= node_count as u64 {
                        return Err(corrupt(format!("carried VC coefficients at node {n}")));
                    }
                    nodes.push(n as usize);
                    for _ in 0..per {
                        values.push(r.f64()?);
                    }
                }
                Ok((nodes, values))
            };
            let (nodes, values) = read_solve(&mut r)?;
            let (span, (before, before_values)) = match version >= 8 {
                true => (r.u32()?, read_solve(&mut r)?),
                false => (0, (Vec::new(), Vec::new())),
            };
            match sim.vc.as_mut() {
                Some(vc) => vc
                    .restore_carried(
                        (nodes, &values),
                        (before, &before_values, span),
                        per,
                        age,
                        node_count,
                    )
                    .map_err(|e| corrupt(e.message))?,
                None if !nodes.is_empty() => {
                    return Err(corrupt("carried VC coefficients without VC"))
                }
                None => {}
            }
        }
        if !r.0.is_empty() {
            return Err(corrupt("the checkpoint has trailing data"));
        }
        Ok(sim)
    }

    /// Loads a simulation saved with [`Sim::save`].
    pub fn load(path: impl AsRef<Path>) -> Result<Self> {
        let path = path.as_ref();
        let bytes = std::fs::read(path).map_err(|e| super::io_error("reading", path, e))?;
        Self::from_checkpoint_bytes(&bytes)
    }
}

/// Checks the frame (magic, version, length, checksum) and returns the dimension.
pub fn checkpoint_dimension(bytes: &[u8]) -> Result<usize> {
    checkpoint_frame(bytes).map(|(_, dim)| dim)
}

/// Checks the frame and returns the format version and the dimension.
fn checkpoint_frame(bytes: &[u8]) -> Result<(u32, usize)> {
    if bytes.len() < 28 || &bytes[..8] != MAGIC {
        return Err(corrupt(
            "not an rkmpm checkpoint (wrong magic or too short)",
        ));
    }
    let word = |k: usize| u32::from_le_bytes(bytes[k..k + 4].try_into().expect("4 bytes"));
    let version = word(8);
    if version == 0 || version > CHECKPOINT_VERSION {
        return Err(Error::new(
            ErrorKind::Unsupported,
            format!(
                "checkpoint format version {version}; this build reads 1 to {CHECKPOINT_VERSION}"
            ),
        ));
    }
    let dim = word(12) as usize;
    let len = u64::from_le_bytes(bytes[16..24].try_into().expect("8 bytes"));
    if len != (bytes.len() - 28) as u64 {
        return Err(corrupt(format!(
            "the checkpoint is truncated or padded: {} payload bytes, header says {len}",
            bytes.len() - 28
        )));
    }
    let payload = &bytes[24..bytes.len() - 4];
    let stored = u32::from_le_bytes(bytes[bytes.len() - 4..].try_into().expect("4 bytes"));
    if crc32fast::hash(payload) != stored {
        return Err(corrupt("the checkpoint fails its checksum (damaged file)"));
    }
    if dim != 2 && dim != 3 {
        return Err(corrupt(format!("dimension {dim} in the checkpoint")));
    }
    Ok((version, dim))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::material::Material;

    /// A small block whose particles the first step sorts: added column by column, so their
    /// order is not the grid blocks' row-major order.
    fn block() -> Sim<2> {
        let mut sim = Sim::<2>::new([0.0, 0.0], [64, 16], 1.0 / 16.0).unwrap();
        let m = sim.add_material(Material::neo_hookean(1000.0, 1e5, 0.3).unwrap());
        let h = 1.0 / 32.0;
        let x: Vec<Vector<2>> = (0..80)
            .flat_map(|i| {
                (0..12).map(move |j| Vector::<2>::new(0.4 + i as f64 * h, 0.1 + j as f64 * h))
            })
            .collect();
        let v: Vec<Vector<2>> = x
            .iter()
            .map(|x| Vector::<2>::new(0.1 * x[1], -0.05))
            .collect();
        sim.add_particles(m, &x, &vec![h * h; x.len()], Some(&v))
            .unwrap();
        sim
    }

    #[test]
    fn version_1_files_load_in_id_order() {
        let sim = block();
        assert!(sim.particles.in_id_order());
        let bytes = sim.encode(1);
        assert_eq!(u32::from_le_bytes(bytes[8..12].try_into().unwrap()), 1);
        let copy = Sim::<2>::from_checkpoint_bytes(&bytes).unwrap();
        assert_eq!(copy.particles, sim.particles);
    }

    /// Format 3 keeps the energy ledger; a format-2 file loads with the accounting off.
    #[test]
    fn the_energy_ledger_is_kept_from_format_3() {
        let mut sim = block();
        sim.set_energy_accounting(true);
        let dt = sim.stable_dt(0.3).unwrap();
        sim.step(dt).unwrap();
        assert!(sim.energy.stress_work != 0.0);
        let copy = Sim::<2>::from_checkpoint_bytes(&sim.checkpoint_bytes()).unwrap();
        assert_eq!(copy.energy, sim.energy);
        let old = Sim::<2>::from_checkpoint_bytes(&sim.encode(2)).unwrap();
        assert_eq!(old.energy, crate::energy::EnergyLedger::default());
        assert_eq!(old.particles, sim.particles);
        // A flag other than 0 or 1 is refused.
        let mut bytes = sim.checkpoint_bytes();
        let flag = bytes.len() - 4 - carried_tail(&sim) - EMPTY_SURFACE_TAIL - 16 - 6 * 8 - 4;
        bytes[flag] = 2;
        refused_as_corrupt(&mut bytes, "energy accounting flag 2");
    }

    /// Format 4 keeps the VC solve's stopping rule; a format-3 file, written when the exact
    /// solve was the default, loads with it. Format 5 keeps whether the rule is the automatic
    /// one (VC2 here, whose automatic rule is not the exact solve).
    #[test]
    fn the_vc_solve_rule_is_kept_from_format_4() {
        let mut sim = block();
        sim.set_integration(crate::Integration::Vc { order: 2 })
            .unwrap();
        let automatic = Sim::<2>::from_checkpoint_bytes(&sim.checkpoint_bytes()).unwrap();
        assert!(automatic.vc_solve_is_automatic());
        assert_eq!(automatic.vc_solve(), sim.vc_solve());
        assert_ne!(sim.vc_solve(), crate::VcSolve::EXACT);
        let rule = crate::VcSolve {
            tolerance: 1e-6,
            max_iterations: 7,
            interval: 1,
        };
        sim.set_vc_solve(rule).unwrap();
        let copy = Sim::<2>::from_checkpoint_bytes(&sim.checkpoint_bytes()).unwrap();
        assert_eq!(copy.vc_solve(), rule);
        let old = Sim::<2>::from_checkpoint_bytes(&sim.encode(3)).unwrap();
        assert_eq!(old.vc_solve(), crate::VcSolve::EXACT);
        // A tolerance the engine refuses is a damaged file.
        let mut bytes = sim.checkpoint_bytes();
        let tolerance = bytes.len() - 4 - carried_tail(&sim) - EMPTY_SURFACE_TAIL - 16;
        bytes[tolerance..tolerance + 8].copy_from_slice(&2.0f64.to_le_bytes());
        refused_as_corrupt(&mut bytes, "tolerance");
    }

    /// Bytes of format 6's tail without a found surface: the refresh interval and the age
    /// (4 bytes each) and the five empty arrays' lengths (8 each).
    const EMPTY_SURFACE_TAIL: usize = 4 + 4 + 5 * 8;

    /// Format 6 keeps the found surface's refresh interval and the surface as carried: a run
    /// saved between refreshes goes on as the uninterrupted run, bit for bit. A format-5 file
    /// loads with the default interval and finds the surface at its first step; an interval of
    /// zero is a damaged file.
    #[test]
    fn the_carried_surface_is_kept_from_format_6() {
        let mut sim = block();
        sim.set_integration(crate::Integration::Vc { order: 1 })
            .unwrap();
        sim.set_vc_surface_refresh(3).unwrap();
        let dt = sim.stable_dt(0.3).unwrap();
        for _ in 0..2 {
            sim.step(dt).unwrap();
        }
        assert_eq!(sim.surface_age, 2);
        let mut copy = Sim::<2>::from_checkpoint_bytes(&sim.checkpoint_bytes()).unwrap();
        assert_eq!(copy.vc_surface_refresh(), 3);
        assert_eq!(copy.vc_surface(), sim.vc_surface());
        for _ in 0..3 {
            sim.step(dt).unwrap();
            copy.step(dt).unwrap();
        }
        assert_eq!(copy.particles, sim.particles);
        assert_eq!(copy.vc_surface(), sim.vc_surface());
        let old = Sim::<2>::from_checkpoint_bytes(&sim.encode(5)).unwrap();
        assert_eq!(old.vc_surface_refresh(), crate::DEFAULT_VC_SURFACE_REFRESH);
        assert!(old.vc_surface().is_empty());
        assert_eq!(old.particles, sim.particles);
        // The interval sits after the solve's rule; the surface's arrays follow it.
        let mut bytes = sim.checkpoint_bytes();
        let surface_bytes = sim.surface.len() * (2 + 2 + 2 + 4) * 8;
        let interval = bytes.len() - 4 - carried_tail(&sim) - EMPTY_SURFACE_TAIL - surface_bytes;
        bytes[interval..interval + 4].copy_from_slice(&0u32.to_le_bytes());
        refused_as_corrupt(&mut bytes, "refresh of zero steps");
    }

    /// Bytes of the tail of formats 7 and 8: the solve's interval and the carried coefficients'
    /// age (4 bytes each), their values a node and their count (8 each), then per node its index
    /// and values; format 8's steps to the solve before (4), its count (8) and its nodes.
    fn carried_tail(sim: &Sim<2>) -> usize {
        let carried = sim.vc.as_ref().map(|vc| vc.carried());
        let solve = |count: usize| carried.map_or(0, |c| count * (1 + c.per()) * 8);
        let count = |before: bool| {
            carried.map_or(0, |c| match before {
                true => c.entries_before().count(),
                false => c.entries().count(),
            })
        };
        4 + 4 + 8 + 8 + solve(count(false)) + 4 + 8 + solve(count(true))
    }

    /// Format 7 keeps the solve's interval and the coefficients carried between solves, format 8
    /// the solve before them too: a run saved between solves goes on as the uninterrupted run,
    /// bit for bit. A format-7 file loads without the solve before, a format-6 file with its
    /// rule solving at every step, as it ran, and nothing carried; a carried node outside the
    /// grid is a damaged file.
    #[test]
    fn the_carried_coefficients_are_kept_from_format_7() {
        let mut sim = block();
        sim.set_vc1_every(3);
        let rule = sim.vc_solve();
        let dt = sim.stable_dt(0.3).unwrap();
        // Solves at steps 1 and 4.
        for _ in 0..5 {
            sim.step(dt).unwrap();
        }
        let carried = |sim: &Sim<2>| sim.vc.as_ref().unwrap().carried().clone();
        assert_eq!((carried(&sim).age, carried(&sim).span()), (1, 3));
        assert!(!carried(&sim).is_empty());
        assert!(carried(&sim).entries_before().count() > 0);
        let seven = Sim::<2>::from_checkpoint_bytes(&sim.encode(7)).unwrap();
        assert_eq!(carried(&seven).span(), 0);
        assert_eq!(
            carried(&seven).entries().count(),
            carried(&sim).entries().count()
        );
        let mut copy = Sim::<2>::from_checkpoint_bytes(&sim.checkpoint_bytes()).unwrap();
        assert_eq!(copy.vc_solve(), rule);
        assert_eq!(carried(&copy), carried(&sim));
        // Steps 6 (carried), 7 (a solve from the carried coefficients) and 8.
        for _ in 0..3 {
            sim.step(dt).unwrap();
            copy.step(dt).unwrap();
        }
        assert_eq!(copy.particles, sim.particles);
        assert_eq!(carried(&copy), carried(&sim));
        let old = Sim::<2>::from_checkpoint_bytes(&sim.encode(6)).unwrap();
        assert_eq!(old.vc_solve().interval, 1);
        assert!(carried(&old).is_empty());
        // The first carried node's index follows the interval, age, size and count.
        let mut bytes = sim.checkpoint_bytes();
        let node = bytes.len() - 4 - carried_tail(&sim) + 24;
        bytes[node..node + 8].copy_from_slice(&u64::MAX.to_le_bytes());
        refused_as_corrupt(&mut bytes, "carried VC coefficients at node");
        // So does the first node of the solve before, after the span and its count.
        let mut bytes = sim.checkpoint_bytes();
        let c = carried(&sim);
        let node = bytes.len() - 4 - carried_tail(&sim)
            + 24
            + c.entries().count() * (1 + c.per()) * 8
            + 12;
        bytes[node..node + 8].copy_from_slice(&u64::MAX.to_le_bytes());
        refused_as_corrupt(&mut bytes, "carried VC coefficients at node");
    }

    /// A checkpoint edited in its payload, its checksum made right again, is refused as a
    /// damaged file with a message containing `what`.
    fn refused_as_corrupt(bytes: &mut [u8], what: &str) {
        let n = bytes.len();
        let crc = crc32fast::hash(&bytes[24..n - 4]).to_le_bytes();
        bytes[n - 4..].copy_from_slice(&crc);
        let e = Sim::<2>::from_checkpoint_bytes(bytes).err().unwrap();
        assert_eq!(e.kind, ErrorKind::CorruptFile, "{e}");
        assert!(e.message.contains(what), "{e}");
    }

    #[test]
    fn sorted_particles_keep_their_ids_and_order() {
        let mut sim = block();
        let dt = sim.stable_dt(0.3).unwrap();
        sim.step(dt).unwrap();
        // The step sorted them: the ids are a permutation, not the identity.
        assert!(!sim.particles.in_id_order());
        let copy = Sim::<2>::from_checkpoint_bytes(&sim.checkpoint_bytes()).unwrap();
        assert_eq!(copy.particles, sim.particles);
        // Ids that are not a permutation are refused.
        sim.particles.id[1] = sim.particles.id[0];
        let e = match Sim::<2>::from_checkpoint_bytes(&sim.checkpoint_bytes()) {
            Err(e) => e,
            Ok(_) => panic!("ids that are not a permutation were accepted"),
        };
        assert_eq!(e.kind, ErrorKind::CorruptFile, "{e}");
        assert!(e.message.contains("permutation"), "{e}");
    }
}
