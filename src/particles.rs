//! Material points, stored as a structure of arrays (one `Vec` per quantity).
//!
//! The step keeps the storage sorted by grid block (`Particles::permute`), so a particle's
//! place in these arrays (its *slot*) changes; its *id*, the index it was added with, does
//! not. What the API hands out is in id order, and only that: `Sim::particles` (a copy in id
//! order), [`Particles::write_field`], the C API's arrays, the VTK files, the pictures, the
//! body-force callback's arrays and the particles named in error messages. The storage order is
//! the engine's own: a caller cannot pair a field with positions in two different orders.

use crate::material::History;
use crate::{Matrix, Vector};
use num_enum::{IntoPrimitive, TryFromPrimitive};
use rayon::prelude::*;

/// Per-particle quantities. All vectors have the same length (the particle count), except
/// `affine`, which is empty unless the APIC transfer runs.
#[derive(Debug, Default, Clone, PartialEq)]
pub struct Particles<const D: usize> {
    /// Current position `x_p`.
    pub(crate) position: Vec<Vector<D>>,
    /// Position at insertion `X_p` (displacement is `x_p − X_p`).
    pub(crate) reference_position: Vec<Vector<D>>,
    pub(crate) velocity: Vec<Vector<D>>,
    /// Deformation gradient `F_p`.
    pub(crate) deformation_gradient: Vec<Matrix<D>>,
    /// Reference volume `V0_p`; the current volume is `det(F_p) V0_p`.
    pub(crate) reference_volume: Vec<f64>,
    pub(crate) mass: Vec<f64>,
    /// Cauchy stress (the in-plane block in 2D).
    pub(crate) stress: Vec<Matrix<D>>,
    /// Pressure `−tr(σ)/3`, out-of-plane stress included in 2D (plane strain).
    pub(crate) pressure: Vec<f64>,
    /// Index into the simulation's materials.
    pub(crate) material: Vec<u32>,
    /// APIC affine velocity matrix `C_p` (empty under PIC/FLIP).
    pub(crate) affine: Vec<Matrix<D>>,
    /// History of elastoplastic materials (`F_e`, plastic strain); empty until particles of a
    /// history material are added, so elastic scenes carry none of it.
    pub(crate) history: Vec<History>,
    /// The id of the particle in each slot: the index it was added with (`0, 1, …` over all
    /// calls to `Sim::add_particles`).
    pub(crate) id: Vec<u32>,
}

/// Buffers [`Particles::permute`] gathers into, one per element type.
#[derive(Debug, Default, Clone)]
pub(crate) struct SpareArrays<const D: usize> {
    vectors: Vec<Vector<D>>,
    matrices: Vec<Matrix<D>>,
    scalars: Vec<f64>,
    indices: Vec<u32>,
    history: Vec<History>,
}

impl<const D: usize> SpareArrays<D> {
    /// Bytes allocated.
    pub fn bytes(&self) -> usize {
        use std::mem::size_of;
        self.vectors.capacity() * size_of::<Vector<D>>()
            + self.matrices.capacity() * size_of::<Matrix<D>>()
            + self.scalars.capacity() * 8
            + self.indices.capacity() * 4
            + self.history.capacity() * size_of::<History>()
    }
}

/// A particle quantity that can be read out, with its layout; the discriminants are the C API's
/// codes (`RKMPM_FIELD_*`).
#[repr(u32)]
#[derive(Debug, Clone, Copy, PartialEq, Eq, TryFromPrimitive, IntoPrimitive)]
pub enum Field {
    /// `dim` values per particle.
    Position = 0,
    /// `dim` values per particle.
    Velocity = 1,
    /// `dim` values per particle, `x_p − X_p`.
    Displacement = 2,
    /// `dim * dim` values per particle, row-major Cauchy stress.
    Stress = 3,
    /// One value per particle.
    Pressure = 4,
    /// One value per particle, current volume `det(F) V0`.
    Volume = 5,
    /// One value per particle.
    Mass = 6,
    /// `dim` values per particle, `X_p`.
    ReferencePosition = 7,
    /// `dim * dim` values per particle, row-major `F_p`.
    DeformationGradient = 8,
    /// One value per particle, equivalent plastic strain (0 for elastic materials).
    PlasticStrain = 9,
    /// One value per particle, damage in [0, 1] (Johnson–Cook; 0 for other materials).
    Damage = 10,
}

impl Field {
    pub const ALL: [Field; 11] = [
        Field::Position,
        Field::Velocity,
        Field::Displacement,
        Field::Stress,
        Field::Pressure,
        Field::Volume,
        Field::Mass,
        Field::ReferencePosition,
        Field::DeformationGradient,
        Field::PlasticStrain,
        Field::Damage,
    ];

    /// Values per particle in dimension `d`.
    pub fn components(self, d: usize) -> usize {
        match self {
            Field::Position | Field::Velocity | Field::Displacement | Field::ReferencePosition => d,
            Field::Stress | Field::DeformationGradient => d * d,
            Field::Pressure
            | Field::Volume
            | Field::Mass
            | Field::PlasticStrain
            | Field::Damage => 1,
        }
    }

    /// Name used in output files.
    pub fn name(self) -> &'static str {
        match self {
            Field::Position => "position",
            Field::Velocity => "velocity",
            Field::Displacement => "displacement",
            Field::Stress => "stress",
            Field::Pressure => "pressure",
            Field::Volume => "volume",
            Field::Mass => "mass",
            Field::ReferencePosition => "reference_position",
            Field::DeformationGradient => "deformation_gradient",
            Field::PlasticStrain => "plastic_strain",
            Field::Damage => "damage",
        }
    }
}

impl<const D: usize> Particles<D> {
    /// Current positions `x_p`.
    pub fn position(&self) -> &[Vector<D>] {
        &self.position
    }
    /// Positions at insertion `X_p` (the displacement is `x_p − X_p`).
    pub fn reference_position(&self) -> &[Vector<D>] {
        &self.reference_position
    }
    pub fn velocity(&self) -> &[Vector<D>] {
        &self.velocity
    }
    /// Deformation gradients `F_p`.
    pub fn deformation_gradient(&self) -> &[Matrix<D>] {
        &self.deformation_gradient
    }
    /// Reference volumes `V0_p`; the current volume is [`Particles::volume`].
    pub fn reference_volume(&self) -> &[f64] {
        &self.reference_volume
    }
    pub fn mass(&self) -> &[f64] {
        &self.mass
    }
    /// Cauchy stresses (the in-plane block in 2D).
    pub fn stress(&self) -> &[Matrix<D>] {
        &self.stress
    }
    /// Pressures `−tr(σ)/3`, the out-of-plane stress included in 2D (plane strain).
    pub fn pressure(&self) -> &[f64] {
        &self.pressure
    }
    /// Each particle's index into the simulation's materials.
    pub fn material(&self) -> &[u32] {
        &self.material
    }
    /// APIC's affine velocity matrices `C_p` (empty under PIC/FLIP).
    pub fn affine(&self) -> &[Matrix<D>] {
        &self.affine
    }
    /// The history of elastoplastic materials (`F_e`, plastic strain, damage); empty when no
    /// particle has a history material.
    pub fn history(&self) -> &[History] {
        &self.history
    }

    pub fn len(&self) -> usize {
        self.position.len()
    }

    pub fn is_empty(&self) -> bool {
        self.position.is_empty()
    }

    /// Bytes allocated.
    pub fn bytes(&self) -> usize {
        use std::mem::size_of;
        let (v, m) = (size_of::<Vector<D>>(), size_of::<Matrix<D>>());
        (self.position.capacity() + self.reference_position.capacity() + self.velocity.capacity())
            * v
            + (self.deformation_gradient.capacity()
                + self.stress.capacity()
                + self.affine.capacity())
                * m
            + (self.reference_volume.capacity() + self.mass.capacity() + self.pressure.capacity())
                * 8
            + (self.material.capacity() + self.id.capacity()) * 4
            + self.history.capacity() * size_of::<History>()
    }

    /// Current volume of particle `p`.
    pub fn volume(&self, p: usize) -> f64 {
        crate::determinant(&self.deformation_gradient[p]) * self.reference_volume[p]
    }

    /// Writes `field` for every particle into `out` in id order, particle-major
    /// (`out[id * components + c]`). `out` must hold `len() * field.components(D)` values.
    pub fn write_field(&self, field: Field, out: &mut [f64]) {
        let k = field.components(D);
        assert_eq!(out.len(), k * self.len(), "output length");
        let values = |p: usize, o: &mut [f64]| match field {
            Field::Position => o.copy_from_slice(self.position[p].as_slice()),
            Field::Velocity => o.copy_from_slice(self.velocity[p].as_slice()),
            Field::ReferencePosition => o.copy_from_slice(self.reference_position[p].as_slice()),
            Field::Displacement => {
                o.copy_from_slice((self.position[p] - self.reference_position[p]).as_slice())
            }
            // Row-major: the transpose of nalgebra's column-major storage.
            Field::Stress => o.copy_from_slice(self.stress[p].transpose().as_slice()),
            Field::DeformationGradient => {
                o.copy_from_slice(self.deformation_gradient[p].transpose().as_slice())
            }
            Field::Pressure => o[0] = self.pressure[p],
            Field::Mass => o[0] = self.mass[p],
            Field::Volume => o[0] = self.volume(p),
            Field::PlasticStrain => o[0] = self.history.get(p).map_or(0.0, |s| s.plastic_strain),
            Field::Damage => o[0] = self.history.get(p).map_or(0.0, |s| s.damage),
        };
        for (p, &id) in self.id.iter().enumerate() {
            let i = id as usize * k;
            values(p, &mut out[i..i + k]);
        }
    }

    /// The slot of each id (the inverse of [`Particles::id`]): `slots()[id]` is where particle
    /// `id` is stored.
    pub(crate) fn slots(&self) -> Vec<usize> {
        let mut slots = vec![0; self.len()];
        for (p, &id) in self.id.iter().enumerate() {
            slots[id as usize] = p;
        }
        slots
    }

    /// A copy in id order: slot `i` holds particle `i` (and `id[i] == i`).
    pub(crate) fn in_id_order_copy(&self) -> Particles<D> {
        let mut copy = self.clone();
        if !self.in_id_order() {
            let order: Vec<u32> = self.slots().iter().map(|&p| p as u32).collect();
            copy.permute(&order, &mut SpareArrays::default());
        }
        copy
    }

    /// Whether every particle is in the slot of its id (nothing sorted yet).
    pub(crate) fn in_id_order(&self) -> bool {
        self.id.iter().enumerate().all(|(p, &id)| id as usize == p)
    }

    /// Stores the particles in the order `order` (a permutation of the slots): the particle in
    /// slot `order[i]` goes to slot `i`, with all its quantities and its id. `spare` lends the
    /// buffers (kept between calls, so a permutation allocates nothing once they have grown).
    pub(crate) fn permute(&mut self, order: &[u32], spare: &mut SpareArrays<D>) {
        assert_eq!(order.len(), self.len(), "a permutation of the particles");
        let s = &mut *spare;
        permute_array(&mut self.position, &mut s.vectors, order);
        permute_array(&mut self.velocity, &mut s.vectors, order);
        permute_array(&mut self.deformation_gradient, &mut s.matrices, order);
        permute_array(&mut self.stress, &mut s.matrices, order);
        permute_array(&mut self.affine, &mut s.matrices, order);
        permute_array(&mut self.pressure, &mut s.scalars, order);
        self.permute_carried(order, spare);
    }

    /// [`Particles::permute`] of the quantities a step carries unchanged (the reference
    /// position and volume, the mass, the material, the id and the history), for a step whose
    /// grid to particle wrote the others in `order` already.
    pub(crate) fn permute_carried(&mut self, order: &[u32], spare: &mut SpareArrays<D>) {
        assert_eq!(order.len(), self.len(), "a permutation of the particles");
        let s = spare;
        permute_array(&mut self.reference_position, &mut s.vectors, order);
        permute_array(&mut self.reference_volume, &mut s.scalars, order);
        permute_array(&mut self.mass, &mut s.scalars, order);
        permute_array(&mut self.material, &mut s.indices, order);
        permute_array(&mut self.id, &mut s.indices, order);
        permute_array(&mut self.history, &mut s.history, order);
    }

    /// Total linear momentum `Σ m_p v_p`.
    pub fn momentum(&self) -> Vector<D> {
        self.mass
            .iter()
            .zip(&self.velocity)
            .map(|(m, v)| *m * v)
            .sum()
    }

    /// Total kinetic energy `½ Σ m_p |v_p|²`.
    pub fn kinetic_energy(&self) -> f64 {
        0.5 * self
            .mass
            .iter()
            .zip(&self.velocity)
            .map(|(m, v)| m * v.norm_squared())
            .sum::<f64>()
    }
}

/// `v` in `order` (`v[order[k]]` at `k`), gathered into `spare`, which takes the old storage.
fn permute_array<T: Copy + Send + Sync>(v: &mut Vec<T>, spare: &mut Vec<T>, order: &[u32]) {
    if v.is_empty() {
        return;
    }
    spare.clear();
    spare.par_extend(order.par_iter().map(|&p| v[p as usize]));
    std::mem::swap(v, spare);
}
