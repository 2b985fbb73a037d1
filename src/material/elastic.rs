//! Elastic models: small-strain linear elasticity and compressible neo-Hookean.

use super::Constitutive;
use crate::error::{check_positive, Error, Result};
use crate::Matrix;
use nalgebra::Matrix3;

/// Density and elastic constants, with the Lamé parameters derived once.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ElasticConstants {
    pub density: f64,
    pub young: f64,
    pub poisson: f64,
    pub lambda: f64,
    pub mu: f64,
}

impl ElasticConstants {
    /// Fails unless density and Young's modulus are positive and `-1 < ν < 0.5`, and (each
    /// with its reason) unless the density is at least [`super::MIN_DENSITY`] and the P-wave
    /// speed `sqrt((λ + 2μ)/ρ)` at most [`super::MAX_WAVE_SPEED`]: outside them no physical
    /// material lies, and the stable step of the fastest could not carry a run to its end.
    pub fn new(density: f64, young: f64, poisson: f64) -> Result<Self> {
        check_positive("density", density)?;
        check_positive("young", young)?;
        if !(poisson > -1.0 && poisson < 0.5) {
            return Err(Error::invalid(format!(
                "poisson must lie in (-1, 0.5), got {poisson}"
            )));
        }
        let mu = young / (2.0 * (1.0 + poisson));
        let lambda = young * poisson / ((1.0 + poisson) * (1.0 - 2.0 * poisson));
        let wave_speed = ((lambda + 2.0 * mu) / density).sqrt();
        if !(lambda.is_finite() && mu.is_finite() && wave_speed.is_finite() && wave_speed > 0.0) {
            return Err(Error::invalid(format!(
                "density {density:e}, young {young:e} and poisson {poisson} give elastic \
                 constants or a wave speed that are not finite and positive (lambda = {lambda:e}, \
                 mu = {mu:e}, c = {wave_speed:e})"
            )));
        }
        super::check_physical(density, wave_speed)?;
        Ok(ElasticConstants {
            density,
            young,
            poisson,
            lambda,
            mu,
        })
    }
}

#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LinearElastic(pub ElasticConstants);

#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NeoHookean(pub ElasticConstants);

impl Constitutive for LinearElastic {
    fn density(&self) -> f64 {
        self.0.density
    }
    fn wave_speed(&self, _j: f64) -> f64 {
        ((self.0.lambda + 2.0 * self.0.mu) / self.0.density).sqrt()
    }
    fn is_elastic(&self) -> bool {
        true
    }
    fn cauchy_stress(&self, f: &Matrix3<f64>) -> Matrix3<f64> {
        let eps = 0.5 * (f + f.transpose()) - Matrix3::identity();
        Matrix3::identity() * (self.0.lambda * eps.trace()) + eps * (2.0 * self.0.mu)
    }
    fn strain_energy_density(&self, f: &Matrix3<f64>) -> f64 {
        let eps = 0.5 * (f + f.transpose()) - Matrix3::identity();
        0.5 * self.0.lambda * eps.trace().powi(2) + self.0.mu * eps.norm_squared()
    }
}

impl Constitutive for NeoHookean {
    fn density(&self) -> f64 {
        self.0.density
    }
    /// From the tangent at `F = J^{1/3} I`: `ρ c² = (λ + 2μ − 2λ ln J) / J` with `ρ = ρ0 / J`.
    fn wave_speed(&self, j: f64) -> f64 {
        self.wave_speed_from_log(j.ln())
    }
    fn is_elastic(&self) -> bool {
        true
    }
    fn cauchy_stress(&self, f: &Matrix3<f64>) -> Matrix3<f64> {
        let j = f.determinant();
        // As `stress_block`, so that the two agree bit for bit.
        self.stress_block_with_log::<3>(f, j, j.ln()).0
    }
    fn strain_energy_density(&self, f: &Matrix3<f64>) -> f64 {
        let lnj = f.determinant().ln();
        0.5 * self.0.mu * ((f.transpose() * f).trace() - 3.0) - self.0.mu * lnj
            + 0.5 * self.0.lambda * lnj * lnj
    }
}

impl LinearElastic {
    /// The `D×D` block of the Cauchy stress and the pressure for a `D×D` deformation gradient
    /// (plane strain in 2D), without the 3×3 embedding: the same values as
    /// [`Constitutive::cauchy_stress`].
    #[inline]
    pub fn stress_block<const D: usize>(&self, f: &Matrix<D>) -> (Matrix<D>, f64) {
        let eps = 0.5 * (f + f.transpose()) - Matrix::<D>::identity();
        // ε_33 = 0 in plane strain.
        let volumetric = self.0.lambda * eps.trace();
        let s = Matrix::<D>::identity() * volumetric + eps * (2.0 * self.0.mu);
        let out_of_plane = if D == 2 { volumetric } else { 0.0 };
        (s, -(s.trace() + out_of_plane) / 3.0)
    }
}

impl NeoHookean {
    /// The P-wave speed `sqrt((λ + 2μ − 2λ ln J) / ρ)` (at least the shear wave speed) given
    /// `ln_j = ln J`: [`Constitutive::wave_speed`].
    #[inline(always)]
    pub fn wave_speed_from_log(&self, ln_j: f64) -> f64 {
        let c2 = (self.0.lambda + 2.0 * self.0.mu - 2.0 * self.0.lambda * ln_j) / self.0.density;
        c2.max(self.0.mu / self.0.density).sqrt()
    }

    /// The `D×D` block of the Cauchy stress and the pressure for a `D×D` deformation gradient
    /// with `j = det f > 0` (plane strain in 2D), without the 3×3 embedding: the same values as
    /// [`Constitutive::cauchy_stress`].
    #[inline(always)]
    pub fn stress_block<const D: usize>(&self, f: &Matrix<D>, j: f64) -> (Matrix<D>, f64) {
        self.stress_block_with_log(f, j, j.ln())
    }

    /// [`NeoHookean::stress_block`] given `ln_j = ln j` (the step takes the logarithm once for
    /// the stress and the wave speed): [`NeoHookean::stress_lanes`] with one lane.
    #[inline(always)]
    pub fn stress_block_with_log<const D: usize>(
        &self,
        f: &Matrix<D>,
        j: f64,
        ln_j: f64,
    ) -> (Matrix<D>, f64) {
        let lanes: [[[f64; 1]; D]; D] =
            std::array::from_fn(|a| std::array::from_fn(|b| [f[(a, b)]]));
        let (mut s, mut pressure) = ([[[0.0; 1]; D]; D], [0.0]);
        self.stress_lanes(&lanes, &[j], &[ln_j], &mut s, &mut pressure);
        (Matrix::<D>::from_fn(|a, b| s[a][b][0]), pressure[0])
    }

    /// The stress of `N` particles at once: `f[a][b][k]` is `F_ab` of particle `k`, `j` and
    /// `ln_j` its `det F > 0` and `ln det F`; writes the `D×D` Cauchy stress into `s` (the same
    /// layout) and the pressure. Each lane takes the same operations in the same order as every
    /// other, whatever `N`, so the compiler can run the lanes in vector registers and a particle's
    /// stress is the same bits alone (`N = 1`, [`NeoHookean::stress_block_with_log`]) or in a
    /// chunk.
    ///
    /// `σ = (μ (b − I) + λ ln J I) / J` with `b = F Fᵀ`; in plane strain `σ_33 = λ ln J / J`.
    #[inline(always)]
    pub fn stress_lanes<const D: usize, const N: usize>(
        &self,
        f: &[[[f64; N]; D]; D],
        j: &[f64; N],
        ln_j: &[f64; N],
        s: &mut [[[f64; N]; D]; D],
        pressure: &mut [f64; N],
    ) {
        let (mu, lambda) = (self.0.mu, self.0.lambda);
        for k in 0..N {
            // One division (the hot loop of grid to particle waits on it).
            let inverse_j = 1.0 / j[k];
            let shear = mu * inverse_j;
            let volumetric = lambda * ln_j[k] * inverse_j;
            let mut trace = 0.0;
            for a in 0..D {
                for c in a..D {
                    // b_ac = Σ_e F_ae F_ce, in the order of e.
                    let mut b = f[a][0][k] * f[c][0][k];
                    for (fa, fc) in f[a][1..].iter().zip(&f[c][1..]) {
                        b += fa[k] * fc[k];
                    }
                    let sigma = if a == c {
                        (b - 1.0) * shear + volumetric
                    } else {
                        b * shear
                    };
                    s[a][c][k] = sigma;
                    s[c][a][k] = sigma;
                }
                trace = if a == 0 {
                    s[0][0][k]
                } else {
                    trace + s[a][a][k]
                };
            }
            // In plane strain b_33 − 1 = 0, so σ_33 is the volumetric term alone.
            let out_of_plane = if D == 2 { volumetric } else { 0.0 };
            pressure[k] = -(trace + out_of_plane) / 3.0;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::material::Material;
    use nalgebra::Rotation3;

    fn small_strain() -> Matrix3<f64> {
        Matrix3::new(1e-6, 2e-7, 0.0, 2e-7, -3e-7, 1e-7, 0.0, 1e-7, 4e-7)
    }

    #[test]
    fn lame_parameters() {
        let c = ElasticConstants::new(1000.0, 2.6, 0.3).unwrap();
        assert!((c.mu - 1.0).abs() < 1e-15);
        assert!((c.lambda - 1.5).abs() < 1e-15);
        assert!(ElasticConstants::new(1000.0, 1.0, 0.5).is_err());
        assert!(ElasticConstants::new(0.0, 1.0, 0.3).is_err());
        assert!(ElasticConstants::new(1.0, -1.0, 0.3).is_err());
    }

    #[test]
    fn stress_free_at_identity_and_linear_limit_agrees() {
        let le = Material::linear_elastic(1000.0, 1e7, 0.3).unwrap();
        let nh = Material::neo_hookean(1000.0, 1e7, 0.3).unwrap();
        assert_eq!(le.cauchy_stress(&Matrix3::identity()).norm(), 0.0);
        assert!(nh.cauchy_stress(&Matrix3::identity()).norm() < 1e-9);
        let f = Matrix3::identity() + small_strain();
        let (sl, sn) = (le.cauchy_stress(&f), nh.cauchy_stress(&f));
        // The models differ at second order in the strain (1e-6): relative 1e-5 is generous.
        assert!((sl - sn).norm() < 1e-5 * sl.norm(), "{sl} vs {sn}");
    }

    /// The block forms take the same operations as the 3×3 forms on the embedded gradient (the
    /// embedding adds exact zeros), so they agree bit for bit.
    #[test]
    fn stress_blocks_equal_the_embedded_three_by_three_stress() {
        use crate::material::{block, embed3, pressure, Constitutive};
        fn check<const D: usize>(m: &Material, f: &crate::Matrix<D>) {
            let j = crate::determinant(f);
            let s3 = m.cauchy_stress(&embed3(f));
            let (s, p) = m.elastic_stress(f, j);
            assert_eq!(s, block::<D>(&s3), "{m:?} {f}");
            assert_eq!(p, pressure(&s3), "{m:?} {f}");
        }
        let models = [
            Material::neo_hookean(1000.0, 1e7, 0.3).unwrap(),
            Material::linear_elastic(1000.0, 1e7, 0.3).unwrap(),
        ];
        let mut x = 0.37_f64;
        let mut next = || {
            x = (x * 9301.0 + 0.49297).fract();
            0.6 * x - 0.3
        };
        for _ in 0..200 {
            let f2 = crate::Matrix::<2>::identity() + crate::Matrix::<2>::from_fn(|_, _| next());
            let f3 = crate::Matrix::<3>::identity() + crate::Matrix::<3>::from_fn(|_, _| next());
            for m in &models {
                if crate::determinant(&f2) > 0.0 {
                    check(m, &f2);
                }
                if crate::determinant(&f3) > 0.0 {
                    check(m, &f3);
                }
            }
        }
    }

    #[test]
    fn neo_hookean_is_objective() {
        let nh = Material::neo_hookean(1000.0, 1e7, 0.3).unwrap();
        let f = Matrix3::new(1.2, 0.3, 0.0, -0.1, 0.9, 0.2, 0.05, 0.0, 1.1);
        let r = Rotation3::from_euler_angles(0.3, -0.7, 1.1).into_inner();
        let s = nh.cauchy_stress(&f);
        let s_rot = nh.cauchy_stress(&(r * f));
        assert!((s_rot - r * s * r.transpose()).norm() < 1e-9 * s.norm());
    }

    /// The stress is the derivative of the energy: `J σ = (∂W/∂F) Fᵀ`, checked by central
    /// differences (step 1e-6: truncation 1e-12, round-off 1e-10 relative).
    #[test]
    fn stress_is_the_derivative_of_the_energy() {
        let f = Matrix3::new(1.1, 0.2, 0.0, -0.1, 0.95, 0.05, 0.02, 0.0, 1.05);
        for m in [
            Material::linear_elastic(1.0, 5.0, 0.3).unwrap(),
            Material::neo_hookean(1.0, 5.0, 0.3).unwrap(),
            Material::drucker_prager(1.0, 5.0, 0.3, 30.0, 0.0, 0.0).unwrap(),
        ] {
            let mut p = Matrix3::zeros();
            let e = 1e-6;
            for i in 0..3 {
                for j in 0..3 {
                    let mut d = Matrix3::zeros();
                    d[(i, j)] = e;
                    p[(i, j)] = (m.strain_energy_density(&(f + d))
                        - m.strain_energy_density(&(f - d)))
                        / (2.0 * e);
                }
            }
            let sigma = m.cauchy_stress(&f);
            match m {
                // Small strain: σ = ∂W/∂ε, the symmetric part of ∂W/∂F.
                Material::LinearElastic(_) => {
                    assert!((0.5 * (p + p.transpose()) - sigma).norm() < 1e-8)
                }
                // Hencky (the elastic law of Drucker–Prager) is hyperelastic too.
                Material::NeoHookean(_)
                | Material::DruckerPrager(_)
                | Material::JohnsonCook(_)
                | Material::Rigid(_) => {
                    let j = f.determinant();
                    assert!((p * f.transpose() / j - sigma).norm() < 1e-8, "{m:?}");
                }
            }
        }
    }

    #[test]
    fn neo_hookean_uniaxial_strain_matches_closed_form() {
        // F = diag(s, 1, 1): σ11 = μ (s² − 1)/s + λ ln s / s.
        let c = ElasticConstants::new(1.0, 3.0, 0.25).unwrap();
        let nh = NeoHookean(c);
        let s = 0.8;
        let f = Matrix3::from_diagonal(&nalgebra::Vector3::new(s, 1.0, 1.0));
        let sig = nh.cauchy_stress(&f);
        let exact = c.mu * (s * s - 1.0) / s + c.lambda * s.ln() / s;
        assert!((sig[(0, 0)] - exact).abs() < 1e-14);
        assert!((sig[(1, 1)] - c.lambda * s.ln() / s).abs() < 1e-14);
    }
}
