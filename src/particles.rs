//! Material points, stored as a structure of arrays (one `Vec` per quantity).

use crate::material::PlasticState;
use crate::{Matrix, Vector};

/// Per-particle quantities. All vectors have the same length (the particle count), except
/// `affine`, which is empty unless the APIC transfer runs.
#[derive(Debug, Default, Clone, PartialEq)]
pub struct Particles<const D: usize> {
    /// Current position `x_p`.
    pub position: Vec<Vector<D>>,
    /// Position at insertion `X_p` (displacement is `x_p − X_p`).
    pub reference_position: Vec<Vector<D>>,
    pub velocity: Vec<Vector<D>>,
    /// Deformation gradient `F_p`.
    pub deformation_gradient: Vec<Matrix<D>>,
    /// Reference volume `V0_p`; the current volume is `det(F_p) V0_p`.
    pub reference_volume: Vec<f64>,
    pub mass: Vec<f64>,
    /// Cauchy stress (the in-plane block in 2D).
    pub stress: Vec<Matrix<D>>,
    /// Pressure `−tr(σ)/3`, out-of-plane stress included in 2D (plane strain).
    pub pressure: Vec<f64>,
    /// Index into the simulation's materials.
    pub material: Vec<u32>,
    /// APIC affine velocity matrix `C_p` (empty under PIC/FLIP).
    pub affine: Vec<Matrix<D>>,
    /// History of elastoplastic materials (`F_e`, plastic strain); empty until particles of a
    /// history material are added, so elastic scenes carry none of it.
    pub plastic: Vec<PlasticState>,
}

/// A particle quantity that can be read out, with its layout.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Field {
    /// `dim` values per particle.
    Position,
    /// `dim` values per particle.
    Velocity,
    /// `dim` values per particle, `x_p − X_p`.
    Displacement,
    /// `dim * dim` values per particle, row-major Cauchy stress.
    Stress,
    /// One value per particle.
    Pressure,
    /// One value per particle, current volume `det(F) V0`.
    Volume,
    /// One value per particle.
    Mass,
    /// `dim` values per particle, `X_p`.
    ReferencePosition,
    /// `dim * dim` values per particle, row-major `F_p`.
    DeformationGradient,
    /// One value per particle, equivalent plastic strain (0 for elastic materials).
    PlasticStrain,
    /// One value per particle, damage in [0, 1] (Johnson–Cook; 0 for other materials).
    Damage,
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
            + self.material.capacity() * 4
            + self.plastic.capacity() * size_of::<PlasticState>()
    }

    /// Current volume of particle `p`.
    pub fn volume(&self, p: usize) -> f64 {
        crate::determinant(&self.deformation_gradient[p]) * self.reference_volume[p]
    }

    /// Writes `field` for every particle into `out`, particle-major
    /// (`out[p * components + c]`). `out` must hold `len() * field.components(D)` values.
    pub fn write_field(&self, field: Field, out: &mut [f64]) {
        let k = field.components(D);
        assert_eq!(out.len(), k * self.len(), "output length");
        let vec = |v: &[Vector<D>], out: &mut [f64]| {
            for (o, x) in out.chunks_exact_mut(D).zip(v) {
                o.copy_from_slice(x.as_slice());
            }
        };
        let mat = |m: &[Matrix<D>], out: &mut [f64]| {
            for (o, x) in out.chunks_exact_mut(D * D).zip(m) {
                // row-major: transpose of nalgebra's column-major storage
                o.copy_from_slice(x.transpose().as_slice());
            }
        };
        match field {
            Field::Position => vec(&self.position, out),
            Field::Velocity => vec(&self.velocity, out),
            Field::ReferencePosition => vec(&self.reference_position, out),
            Field::Displacement => {
                for (p, o) in out.chunks_exact_mut(D).enumerate() {
                    o.copy_from_slice((self.position[p] - self.reference_position[p]).as_slice());
                }
            }
            Field::Stress => mat(&self.stress, out),
            Field::DeformationGradient => mat(&self.deformation_gradient, out),
            Field::Pressure => out.copy_from_slice(&self.pressure),
            Field::Mass => out.copy_from_slice(&self.mass),
            Field::Volume => {
                for (p, o) in out.iter_mut().enumerate() {
                    *o = self.volume(p);
                }
            }
            Field::PlasticStrain => {
                for (p, o) in out.iter_mut().enumerate() {
                    *o = self.plastic.get(p).map_or(0.0, |s| s.plastic_strain);
                }
            }
            Field::Damage => {
                for (p, o) in out.iter_mut().enumerate() {
                    *o = self.plastic.get(p).map_or(0.0, |s| s.damage);
                }
            }
        }
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
