//! Elastoplasticity in finite strain with per-particle history: Drucker–Prager for soils.
//!
//! Multiplicative split `F = F_e F_p`. The elastic response is Hencky's: with `F_e = U Σ Vᵀ` and
//! the logarithmic principal strains `ε = ln Σ`, the Kirchhoff stress is
//! `τ = U diag(λ tr ε + 2 μ ε) Uᵀ` and the Cauchy stress `σ = τ / J`. Each step takes the elastic
//! predictor `F_e^tr = ΔF F_e^n` (`ΔF = F^{n+1} (F^n)⁻¹`) and returns the principal Kirchhoff
//! stress to the yield surface. The elastic law is linear in `ε`, so for the linear
//! Drucker–Prager surface the return is in closed form, apex included (de Souza Neto, Perić &
//! Owen 2008, section 8.3; Bui et al. 2008 for the plane-strain fit to Mohr–Coulomb).

use super::ElasticConstants;
use crate::error::{check_finite, Error, Result};
use nalgebra::{Matrix3, Vector3};

/// History of one material point under an elastoplastic model.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct History {
    /// Elastic part `F_e` of the deformation gradient (3×3; plane strain keeps `F_33 = 1` for the
    /// total `F`, not for `F_e`).
    pub elastic_deformation: Matrix3<f64>,
    /// Equivalent plastic strain `∫ sqrt(2/3 ‖dε_p‖²)`.
    pub plastic_strain: f64,
    /// Damage `D ∈ [0, 1]` (Johnson–Cook; 1 = failed).
    pub damage: f64,
    /// Temperature rise above room temperature from plastic work (K).
    pub heating: f64,
}

impl Default for History {
    fn default() -> Self {
        History {
            elastic_deformation: Matrix3::identity(),
            plastic_strain: 0.0,
            damage: 0.0,
            heating: 0.0,
        }
    }
}

/// Drucker–Prager plasticity with a non-associated flow rule, fitted to Mohr–Coulomb in plane
/// strain: yield `f = α_φ I1 + sqrt(J2) − k_c ≤ 0` on the Kirchhoff stress (tension positive),
/// plastic potential `g = α_ψ I1 + sqrt(J2)`, with
/// `α_φ = tan φ / sqrt(9 + 12 tan² φ)`, `k_c = 3 c / sqrt(9 + 12 tan² φ)` and `α_ψ` likewise
/// from the dilatancy angle `ψ`. Perfectly plastic (no hardening). Stress states beyond the apex
/// `I1 = k_c / α_φ` return to it: a cohesionless soil carries no tension.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DruckerPrager {
    pub elastic: ElasticConstants,
    /// Friction angle `φ` in radians.
    pub friction: f64,
    /// Cohesion `c` (Pa).
    pub cohesion: f64,
    /// Dilatancy angle `ψ` in radians (`0 ≤ ψ ≤ φ`; `ψ = φ` is associated flow).
    pub dilatancy: f64,
    alpha_friction: f64,
    alpha_dilatancy: f64,
    k_cohesion: f64,
    /// The μ(I) rate dependence of the friction, if any.
    pub rheology: Option<InertialRheology>,
}

/// The μ(I) rheology of dense granular flow (GDR MiDi 2004; Jop, Forterre & Pouliquen 2006)
/// added to Drucker–Prager's friction: at an equivalent plastic shear rate `γ̇` and pressure `p`
/// the inertial number is `I = γ̇ d / sqrt(p / ρ)` and the friction coefficient on
/// `sqrt(J2) / p` rises from the static `μ_s = 3 α_φ` by `Δμ I / (I_0 + I)`. The rate is the
/// step's plastic multiplier over `dt` (`sqrt(J2)` falls by `G γ̇ dt`, as in Dunatunga & Kamrin
/// 2015), found with the stress in the same return (no lag).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct InertialRheology {
    /// `Δμ = μ_2 − μ_s`, the friction gained at large inertial numbers (≥ 0).
    pub friction_increase: f64,
    /// `I_0 > 0`, the inertial number at which half of `Δμ` is gained.
    pub reference_inertial_number: f64,
    /// Grain diameter `d > 0` (m).
    pub grain_diameter: f64,
}

impl InertialRheology {
    /// Checks the constants.
    pub fn new(
        friction_increase: f64,
        reference_inertial_number: f64,
        grain_diameter: f64,
    ) -> Result<Self> {
        check_finite("friction_increase", friction_increase)?;
        if friction_increase < 0.0 {
            return Err(Error::invalid(format!(
                "friction_increase must be >= 0, got {friction_increase}"
            )));
        }
        crate::error::check_positive("reference_inertial_number", reference_inertial_number)?;
        crate::error::check_positive("grain_diameter", grain_diameter)?;
        Ok(InertialRheology {
            friction_increase,
            reference_inertial_number,
            grain_diameter,
        })
    }

    /// The friction gained `Δμ I / (I_0 + I)` at inertial number `I`.
    pub fn friction_gain(&self, inertial_number: f64) -> f64 {
        self.friction_increase * inertial_number
            / (self.reference_inertial_number + inertial_number)
    }
}

fn mohr_coulomb_fit(angle: f64) -> (f64, f64) {
    let t = angle.tan();
    let r = (9.0 + 12.0 * t * t).sqrt();
    (t / r, 3.0 / r)
}

impl DruckerPrager {
    /// Angles in degrees. Fails unless `0 ≤ φ < 90°`, `0 ≤ ψ ≤ φ` and `c ≥ 0`, all finite.
    pub fn new(
        elastic: ElasticConstants,
        friction_degrees: f64,
        cohesion: f64,
        dilatancy_degrees: f64,
    ) -> Result<Self> {
        check_finite("friction_angle", friction_degrees)?;
        check_finite("cohesion", cohesion)?;
        check_finite("dilatancy_angle", dilatancy_degrees)?;
        if !(0.0..90.0).contains(&friction_degrees) {
            return Err(Error::invalid(format!(
                "friction_angle must lie in [0, 90) degrees, got {friction_degrees}"
            )));
        }
        if !(0.0..=friction_degrees).contains(&dilatancy_degrees) {
            return Err(Error::invalid(format!(
                "dilatancy_angle must lie in [0, friction_angle = {friction_degrees}] degrees, got {dilatancy_degrees}"
            )));
        }
        if cohesion < 0.0 {
            return Err(Error::invalid(format!(
                "cohesion must be >= 0, got {cohesion}"
            )));
        }
        if friction_degrees == 0.0 && cohesion == 0.0 {
            return Err(Error::invalid(
                "friction_angle and cohesion are both zero: the material has no strength",
            ));
        }
        let (friction, dilatancy) = (
            friction_degrees.to_radians(),
            dilatancy_degrees.to_radians(),
        );
        let (alpha_friction, k) = mohr_coulomb_fit(friction);
        let (alpha_dilatancy, _) = mohr_coulomb_fit(dilatancy);
        Ok(DruckerPrager {
            elastic,
            friction,
            cohesion,
            dilatancy,
            alpha_friction,
            alpha_dilatancy,
            k_cohesion: k * cohesion,
            rheology: None,
        })
    }

    /// The same soil with the μ(I) rate dependence of its friction.
    pub fn with_rheology(self, rheology: Option<InertialRheology>) -> Self {
        DruckerPrager { rheology, ..self }
    }

    /// Number of stored constants besides the elastic ones (for checkpoints): the six of the
    /// yield surface, then `Δμ, I_0, d` of the rheology (`d = 0`: none).
    pub(crate) const STORED: usize = 9;
    /// The stored constants of the yield surface alone.
    pub(crate) const STORED_YIELD: usize = 6;

    /// The constants as stored, derived ones included, so a restored model is bit-identical.
    pub(crate) fn stored_constants(&self) -> [f64; Self::STORED] {
        let r = self.rheology.map_or([0.0; 3], |r| {
            [
                r.friction_increase,
                r.reference_inertial_number,
                r.grain_diameter,
            ]
        });
        [
            self.friction,
            self.cohesion,
            self.dilatancy,
            self.alpha_friction,
            self.alpha_dilatancy,
            self.k_cohesion,
            r[0],
            r[1],
            r[2],
        ]
    }

    /// The inverse of [`DruckerPrager::stored_constants`].
    pub(crate) fn from_stored(elastic: ElasticConstants, c: &[f64]) -> Self {
        DruckerPrager {
            elastic,
            friction: c[0],
            cohesion: c[1],
            dilatancy: c[2],
            alpha_friction: c[3],
            alpha_dilatancy: c[4],
            k_cohesion: c[5],
            rheology: (c[8] > 0.0).then_some(InertialRheology {
                friction_increase: c[6],
                reference_inertial_number: c[7],
                grain_diameter: c[8],
            }),
        }
    }

    /// The yield function `α_φ I1 + sqrt(J2) − k_c` of a principal Kirchhoff stress.
    pub fn yield_function(&self, tau: &Vector3<f64>) -> f64 {
        let i1 = tau.sum();
        let s = tau - Vector3::repeat(i1 / 3.0);
        self.alpha_friction * i1 + (0.5 * s.norm_squared()).sqrt() - self.k_cohesion
    }

    /// Principal Kirchhoff stress of principal logarithmic strains.
    pub fn principal_stress(&self, eps: &Vector3<f64>) -> Vector3<f64> {
        let (l, m) = (self.elastic.lambda, self.elastic.mu);
        Vector3::repeat(l * eps.sum()) + 2.0 * m * eps
    }

    /// Returns the trial principal strains `eps` to the yield surface: the new principal strains
    /// (rate-independent).
    pub fn return_map(&self, eps: &Vector3<f64>) -> Vector3<f64> {
        self.return_map_over(eps, f64::INFINITY)
    }

    /// [`DruckerPrager::return_map`] over a step `dt`: with the μ(I) rheology the friction rises
    /// with the plastic shear rate of this return.
    pub fn return_map_over(&self, eps: &Vector3<f64>, dt: f64) -> Vector3<f64> {
        let (m, k) = (
            self.elastic.mu,
            self.elastic.lambda + 2.0 / 3.0 * self.elastic.mu,
        );
        let tau = self.principal_stress(eps);
        let f = self.yield_function(&tau);
        // Relative tolerance against the stress scale: round-off of τ is ~1e-16 E ‖ε‖.
        if f <= 1e-14 * self.elastic.young * (1.0 + eps.norm()) {
            return *eps;
        }
        let i1 = tau.sum();
        let s = tau - Vector3::repeat(i1 / 3.0);
        let sqrt_j2 = (0.5 * s.norm_squared()).sqrt();
        let mut gamma = f / (9.0 * k * self.alpha_friction * self.alpha_dilatancy + m);
        if let Some(r) = self.rheology.filter(|_| dt.is_finite()) {
            if sqrt_j2 - m * gamma >= 0.0 {
                gamma = self.rate_dependent_multiplier(&r, sqrt_j2, i1, gamma, dt);
            }
        }
        let sqrt_j2_new = sqrt_j2 - m * gamma;
        let (i1_new, s_new) = if sqrt_j2_new >= 0.0 {
            let scale = if sqrt_j2 > 0.0 {
                sqrt_j2_new / sqrt_j2
            } else {
                0.0
            };
            (i1 - 9.0 * k * self.alpha_dilatancy * gamma, s * scale)
        } else {
            // Apex (α_φ > 0 here: for φ = 0 the smooth return always lands at sqrt(J2) = k_c).
            (self.k_cohesion / self.alpha_friction, Vector3::zeros())
        };
        s_new / (2.0 * m) + Vector3::repeat(i1_new / (9.0 * k))
    }

    /// The plastic multiplier `γ` of the return under the μ(I) rheology: the root of
    /// `g(γ) = sqrt(J2)^tr − G γ − (μ_s + Δμ I/(I_0 + I)) p(γ) − k_c` with
    /// `p(γ) = p^tr + 3 K α_ψ γ` (Kirchhoff pressure, compression positive) and
    /// `I = (γ / dt) d / sqrt(p / ρ)`. `g(0) = f > 0` and `g(γ_s) ≤ 0` at the rate-independent
    /// multiplier `γ_s`, since the friction only rises: bisection to round-off on `[0, γ_s]`.
    fn rate_dependent_multiplier(
        &self,
        r: &InertialRheology,
        sqrt_j2: f64,
        i1: f64,
        gamma_static: f64,
        dt: f64,
    ) -> f64 {
        let (m, k) = (
            self.elastic.mu,
            self.elastic.lambda + 2.0 / 3.0 * self.elastic.mu,
        );
        let rho = self.elastic.density;
        let g = |gamma: f64| {
            let p = -(i1 - 9.0 * k * self.alpha_dilatancy * gamma) / 3.0;
            let mu_s = 3.0 * self.alpha_friction;
            let friction = if p > 0.0 {
                mu_s + r.friction_gain(gamma / dt * r.grain_diameter / (p / rho).sqrt())
            } else {
                mu_s
            };
            sqrt_j2 - m * gamma - friction * p - self.k_cohesion
        };
        let (mut lo, mut hi) = (0.0, gamma_static);
        for _ in 0..200 {
            let mid = 0.5 * (lo + hi);
            if mid <= lo || mid >= hi {
                break;
            }
            if g(mid) > 0.0 {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        hi
    }

    /// One constitutive update: the new state and Cauchy stress after the increment `df`, for a
    /// total `det F = j`, over the step `dt` (which only the μ(I) rheology uses).
    pub fn update(
        &self,
        state: &History,
        df: &Matrix3<f64>,
        j: f64,
        dt: f64,
    ) -> (History, Matrix3<f64>) {
        let fe = df * state.elastic_deformation;
        let (u, eps, vt) = hencky_frame(&fe, true);
        let eps_new = self.return_map_over(&eps, dt);
        let tau = self.principal_stress(&eps_new);
        let fe_new = match vt {
            Some(vt) => u * Matrix3::from_diagonal(&eps_new.map(f64::exp)) * vt,
            // `F_e = U Σ Vᵀ` with `Vᵀ = Σ⁻¹ Uᵀ F_e`: the new `F_e = U diag(e^ε' / e^ε) Uᵀ F_e`.
            None => u * Matrix3::from_diagonal(&(eps_new - eps).map(f64::exp)) * u.transpose() * fe,
        };
        let sigma = u * Matrix3::from_diagonal(&tau) * u.transpose() / j;
        let plastic = (2.0f64 / 3.0).sqrt() * (eps - eps_new).norm();
        (
            History {
                elastic_deformation: fe_new,
                plastic_strain: state.plastic_strain + plastic,
                ..*state
            },
            sigma,
        )
    }

    /// Hencky Cauchy stress `U diag(λ tr ε + 2 μ ε) Uᵀ / j` of an elastic deformation `fe`.
    pub fn elastic_stress(&self, fe: &Matrix3<f64>, j: f64) -> Matrix3<f64> {
        let (u, eps, _) = hencky_frame(fe, false);
        let tau = self.principal_stress(&eps);
        u * Matrix3::from_diagonal(&tau) * u.transpose() / j
    }

    /// Hencky energy of the elastic part `F_e` per unit reference volume.
    pub fn elastic_energy(&self, fe: &Matrix3<f64>) -> f64 {
        let eps = match plane_strain_hencky(fe) {
            Some((_, eps)) => eps,
            None => fe.svd(false, false).singular_values.map(|s| s.ln()),
        };
        0.5 * self.elastic.lambda * eps.sum().powi(2) + self.elastic.mu * eps.norm_squared()
    }
}

/// `F_e`'s left singular vectors `U` and logarithmic principal strains `ε = ln Σ`: in closed form
/// in plane strain ([`plane_strain_hencky`], `Vᵀ` not given), else by the SVD (with `Vᵀ` when
/// `with_vt`).
fn hencky_frame(
    fe: &Matrix3<f64>,
    with_vt: bool,
) -> (Matrix3<f64>, Vector3<f64>, Option<Matrix3<f64>>) {
    if let Some((u, eps)) = plane_strain_hencky(fe) {
        return (u, eps, None);
    }
    let svd = fe.svd(true, with_vt);
    let eps = svd.singular_values.map(|s| s.ln());
    (svd.u.expect("U"), eps, svd.v_t)
}

/// The left singular vectors `U` and logarithmic principal strains `ε = ln Σ` of a plane-strain
/// `F_e` (nothing couples the plane and the third axis, `F_e33 > 0`), in closed form from the
/// in-plane block `A` of `F_e`: the eigenvalues of `A Aᵀ = [[p, q], [q, r]]` are
/// `λ1 = m + s` (`m = (p + r)/2`, `s = hypot((p − r)/2, q)`) and `λ2 = (det A)² / λ1` (no
/// cancellation when `λ2 ≪ λ1`), and its eigenvectors the rotation by `θ` with
/// `(cos 2θ, sin 2θ) = ((p − r)/2, q) / s`, taken by the half angle that does not cancel.
/// `None` for any other `F_e` (3D, or an inverted plane), which the SVD handles. A third of the
/// time of nalgebra's 3 × 3 SVD; the two agree to round-off
/// (`plane_strain_hencky_agrees_with_the_svd`).
fn plane_strain_hencky(fe: &Matrix3<f64>) -> Option<(Matrix3<f64>, Vector3<f64>)> {
    let coupled = fe[(0, 2)] != 0.0 || fe[(1, 2)] != 0.0 || fe[(2, 0)] != 0.0 || fe[(2, 1)] != 0.0;
    let (a, b, c, d) = (fe[(0, 0)], fe[(0, 1)], fe[(1, 0)], fe[(1, 1)]);
    let det = a * d - b * c;
    if coupled || !(fe[(2, 2)] > 0.0 && det > 0.0) {
        return None;
    }
    let (p, q, r) = (a * a + b * b, a * c + b * d, c * c + d * d);
    let (half, m) = (0.5 * (p - r), 0.5 * (p + r));
    let s = half.hypot(q);
    let lambda1 = m + s;
    let lambda2 = det * det / lambda1;
    let (cos, sin) = if s == 0.0 {
        (1.0, 0.0)
    } else if half >= 0.0 {
        let cos = (0.5 * (1.0 + half / s)).sqrt();
        (cos, q / (2.0 * s * cos))
    } else {
        let sin = (0.5 * (1.0 - half / s)).sqrt().copysign(q);
        (q / (2.0 * s * sin), sin)
    };
    let u = Matrix3::new(cos, -sin, 0.0, sin, cos, 0.0, 0.0, 0.0, 1.0);
    let eps = Vector3::new(0.5 * lambda1.ln(), 0.5 * lambda2.ln(), fe[(2, 2)].ln());
    Some((u, eps))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::shape::UniformRng;

    fn sand() -> DruckerPrager {
        DruckerPrager::new(
            ElasticConstants::new(2650.0, 8.4e5, 0.3).unwrap(),
            20.0,
            0.0,
            0.0,
        )
        .unwrap()
    }

    /// μ(I): a trial state sheared past the yield surface returns onto
    /// `sqrt(J2) = (μ_s + Δμ I / (I_0 + I)) p`, with `I` from the shear rate of that very return
    /// (`γ / dt`, `G γ` the fall of `sqrt(J2)`), to round-off; the friction lies between `μ_s`
    /// and `μ_s + Δμ` and rises with the rate (the same trial over shorter steps, `I` from 0.01
    /// to 10); with dilatancy the pressure the rate is taken at moves with the return, and the
    /// same holds; a vanishing grain diameter gives the rate-independent return.
    #[test]
    fn mu_of_i_returns_onto_the_rate_dependent_surface() {
        let rheology = InertialRheology::new(0.26, 0.28, 1.25e-3).unwrap();
        let shear = 5e-3;
        let eps = Vector3::new(-1e-3 + shear, -1e-3 - shear, -1e-3);
        for dilatancy in [0.0, 10.0] {
            let base = DruckerPrager::new(
                ElasticConstants::new(2650.0, 8.4e5, 0.3).unwrap(),
                20.0,
                0.0,
                dilatancy,
            )
            .unwrap();
            let dp = base.with_rheology(Some(rheology));
            let mu_s = 3.0 * dp.alpha_friction;
            let invariants = |tau: &Vector3<f64>| {
                let p = -tau.sum() / 3.0;
                ((0.5 * (tau + Vector3::repeat(p)).norm_squared()).sqrt(), p)
            };
            let (trial, _) = invariants(&dp.principal_stress(&eps));
            let mut last = mu_s;
            for dt in [1e-3, 1e-4, 1e-5, 1e-6] {
                let (q, p) = invariants(&dp.principal_stress(&dp.return_map_over(&eps, dt)));
                let rate = (trial - q) / dp.elastic.mu / dt;
                let i = rate * rheology.grain_diameter / (p / dp.elastic.density).sqrt();
                let mu = q / p;
                assert!(
                    (mu - mu_s - rheology.friction_gain(i)).abs() < 1e-9,
                    "ψ {dilatancy}, dt {dt}: μ {mu}, μ(I = {i}) {}",
                    mu_s + rheology.friction_gain(i)
                );
                assert!(
                    mu > last && mu < mu_s + 0.26,
                    "ψ {dilatancy}, dt {dt}: μ {mu}"
                );
                last = mu;
            }
            assert!(
                last > mu_s + 0.2,
                "the fastest step gains most of Δμ: {last}"
            );
            let grainless =
                base.with_rheology(Some(InertialRheology::new(0.26, 0.28, 1e-30).unwrap()));
            let (a, b) = (grainless.return_map_over(&eps, 1e-4), base.return_map(&eps));
            assert!((a - b).norm() < 1e-12 * b.norm(), "{a} against {b}");
        }
        assert!(InertialRheology::new(-0.1, 0.28, 1e-3).is_err());
        assert!(InertialRheology::new(0.26, 0.0, 1e-3).is_err());
        assert!(InertialRheology::new(0.26, 0.28, f64::NAN).is_err());
    }

    fn random_strain(rng: &mut UniformRng, size: f64) -> Vector3<f64> {
        Vector3::from_fn(|_, _| size * (2.0 * rng.uniform() - 1.0))
    }

    /// After the return no stress lies outside the yield surface (to round-off), a stress inside
    /// it is left alone, and a returned stress returns to itself.
    #[test]
    fn return_map_lands_on_the_yield_surface() {
        let mut rng = UniformRng::new(3);
        for dp in [
            sand(),
            DruckerPrager::new(
                ElasticConstants::new(2000.0, 1e7, 0.25).unwrap(),
                30.0,
                5e3,
                10.0,
            )
            .unwrap(),
            DruckerPrager::new(
                ElasticConstants::new(2000.0, 1e7, 0.25).unwrap(),
                35.0,
                0.0,
                35.0,
            )
            .unwrap(),
            DruckerPrager::new(
                ElasticConstants::new(2000.0, 1e7, 0.25).unwrap(),
                0.0,
                1e4,
                0.0,
            )
            .unwrap(),
        ] {
            let scale = dp.elastic.young;
            let (mut plastic, mut elastic) = (0, 0);
            for _ in 0..2000 {
                // Sizes from 5e-6 to 5e-2 (log-uniform), elastic and plastic states alike.
                let size = 0.05 * 10f64.powf(-4.0 * rng.uniform());
                let eps = random_strain(&mut rng, size);
                let f_trial = dp.yield_function(&dp.principal_stress(&eps));
                let back = dp.return_map(&eps);
                let f = dp.yield_function(&dp.principal_stress(&back));
                assert!(f <= 1e-12 * scale, "{dp:?}: f = {f} after return");
                if f_trial <= 0.0 {
                    elastic += 1;
                    assert_eq!(back, eps);
                } else {
                    plastic += 1;
                    assert!(f.abs() <= 1e-10 * scale, "not on the surface: {f}");
                    let again = dp.return_map(&back);
                    assert!((again - back).norm() <= 1e-14, "return is not idempotent");
                }
            }
            assert!(
                plastic > 100 && elastic > 100,
                "{plastic} plastic, {elastic} elastic"
            );
        }
    }

    /// The plastic strain increment follows the potential `g`:
    /// `Δε_p = Δγ (α_ψ I + s / (2 sqrt(J2)))`, so `tr Δε_p = 3 α_ψ Δγ` and
    /// `‖dev Δε_p‖ = Δγ / sqrt(2)`. Zero dilatancy: no plastic volume change; ψ = φ: associated.
    #[test]
    fn flow_is_non_associated_with_the_dilatancy_angle() {
        let e = ElasticConstants::new(2000.0, 1e7, 0.25).unwrap();
        for psi in [0.0, 10.0, 30.0] {
            let dp = DruckerPrager::new(e, 30.0, 2e4, psi).unwrap();
            // A deviatoric trial strain under some compression: smooth-cone return.
            let eps = Vector3::new(-0.01, 0.004, -0.001);
            let back = dp.return_map(&eps);
            let dep = eps - back;
            let gamma = (2.0f64).sqrt() * (dep - Vector3::repeat(dep.sum() / 3.0)).norm();
            let (alpha_psi, _) = mohr_coulomb_fit(psi.to_radians());
            assert!(gamma > 1e-4, "expected plastic flow");
            assert!(
                (dep.sum() - 3.0 * alpha_psi * gamma).abs() < 1e-12,
                "ψ = {psi}: tr Δε_p = {}, 3 α_ψ Δγ = {}",
                dep.sum(),
                3.0 * alpha_psi * gamma
            );
        }
    }

    /// Tension beyond the apex of a cohesionless soil returns to zero stress; with cohesion, to the
    /// apex `I1 = k_c / α_φ` with no deviator.
    #[test]
    fn apex_return() {
        let eps = Vector3::new(0.01, 0.012, 0.008);
        let back = sand().return_map(&eps);
        assert!(sand().principal_stress(&back).norm() < 1e-9);
        let e = ElasticConstants::new(2000.0, 1e7, 0.25).unwrap();
        let dp = DruckerPrager::new(e, 30.0, 1e4, 5.0).unwrap();
        let tau = dp.principal_stress(&dp.return_map(&eps));
        let i1 = tau.sum();
        assert!((i1 - dp.k_cohesion / dp.alpha_friction).abs() < 1e-9 * i1.abs());
        assert!((tau - Vector3::repeat(i1 / 3.0)).norm() < 1e-9 * i1.abs());
    }

    /// A full update under a rotation leaves the stress rotated (objectivity) and the plastic
    /// strain unchanged; uniaxial compression of sand yields and stays on the surface.
    #[test]
    fn update_is_objective_and_accumulates_plastic_strain() {
        let dp = sand();
        let mut state = History::default();
        let df = Matrix3::from_diagonal(&Vector3::new(0.995, 1.0, 1.0));
        let mut j = 1.0;
        let mut sigma = Matrix3::zeros();
        for _ in 0..20 {
            j *= 0.995;
            (state, sigma) = dp.update(&state, &df, j, 1e-4);
        }
        assert!(state.plastic_strain > 0.0);
        let eig = (sigma * j).symmetric_eigenvalues();
        assert!(dp.yield_function(&eig) <= 1e-9 * dp.elastic.young);
        let r = nalgebra::Rotation3::from_euler_angles(0.4, -0.2, 0.9).into_inner();
        let (rotated, sigma_r) = dp.update(&state, &r, j, 1e-4);
        assert!((sigma_r - r * sigma * r.transpose()).norm() < 1e-9 * sigma.norm());
        assert_eq!(rotated.plastic_strain, state.plastic_strain);
    }

    /// The closed form of plane strain against nalgebra's SVD, on random in-plane `F_e` (stretches
    /// up to 3 and down to 1/3, with shear; near-equal stretches; the identity; a pure
    /// rotation): the same principal strains, the same `U diag(ε) Uᵀ` (which does not depend
    /// on how `U` is chosen where stretches are equal) to 1e-14 of the strains' scale, and
    /// `U` orthogonal. The update through either (most of the cases flow) gives the same `F_e`
    /// to 1e-14 (measured 1.1e-15) and the same stress to 1e-14 of `E` plus the stress (the
    /// round-off of `E ε`; measured 0.096 of that).
    #[test]
    fn plane_strain_hencky_agrees_with_the_svd() {
        let mut rng = UniformRng::new(3);
        let mut cases: Vec<Matrix3<f64>> = (0..2000)
            .map(|k| {
                let size = [1e-9, 1e-3, 0.3, 1.0][k % 4];
                let mut f = Matrix3::identity();
                for e in [(0, 0), (0, 1), (1, 0), (1, 1)] {
                    f[e] += size * (rng.uniform() - 0.5);
                }
                f[(2, 2)] = 1.0 + 0.1 * (rng.uniform() - 0.5);
                f
            })
            .collect();
        let turn = nalgebra::Rotation3::from_euler_angles(0.0, 0.0, 0.7).into_inner();
        cases.extend([
            Matrix3::identity(),
            turn,
            turn * Matrix3::new(3.0, 0.0, 0.0, 0.0, 1.0 / 3.0, 0.0, 0.0, 0.0, 1.0),
        ]);
        let dp = sand();
        let (young, mut plastic) = (dp.elastic.young, 0);
        for fe in &cases {
            let Some((u, eps)) = plane_strain_hencky(fe) else {
                panic!("{fe}")
            };
            let svd = fe.svd(true, true);
            let log = svd.singular_values.map(f64::ln);
            let scale = 1e-14 * (1.0 + log.amax());
            let mut sorted = eps;
            sorted.as_mut_slice().sort_by(|a, b| b.total_cmp(a));
            assert!((sorted - log).amax() <= scale, "{fe}: {eps} {log}");
            let us = svd.u.unwrap();
            let ours = u * Matrix3::from_diagonal(&eps) * u.transpose();
            let theirs = us * Matrix3::from_diagonal(&log) * us.transpose();
            assert!((ours - theirs).amax() <= scale, "{fe}");
            assert!((u.transpose() * u - Matrix3::identity()).amax() <= 1e-15);
            // The whole update, which also takes the 3 × 3 SVD when the plane is coupled.
            let state = History {
                elastic_deformation: *fe,
                ..History::default()
            };
            let mut coupled = *fe;
            coupled[(0, 2)] = 1e-300;
            let (a, sa) = dp.update(&state, &Matrix3::identity(), fe.determinant(), 1e-4);
            let state_b = History {
                elastic_deformation: coupled,
                ..state
            };
            let (b, sb) = dp.update(&state_b, &Matrix3::identity(), fe.determinant(), 1e-4);
            // The stress's round-off is that of `E ε`: bounded against `E` and the stress.
            let bound = 1e-14 * (young + sb.amax());
            assert!((sa - sb).amax() <= bound, "{fe}: {sa} {sb}");
            assert!(
                (a.elastic_deformation - b.elastic_deformation).amax() <= 1e-14,
                "{fe}"
            );
            plastic += (a.plastic_strain > 0.0) as usize;
            assert!((a.plastic_strain - b.plastic_strain).abs() <= 1e-12);
        }
        assert!(plastic > 500, "{plastic} of the cases flow");
        // Coupled, inverted or flattened: the SVD's.
        let mut coupled = Matrix3::identity();
        coupled[(2, 0)] = 0.1;
        let flip = Matrix3::from_diagonal(&Vector3::new(-1.0, 1.0, 1.0));
        for fe in [
            coupled,
            flip,
            Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, 0.0)),
        ] {
            assert!(plane_strain_hencky(&fe).is_none(), "{fe}");
        }
    }

    #[test]
    fn rejects_bad_parameters() {
        let e = ElasticConstants::new(2000.0, 1e7, 0.25).unwrap();
        assert!(DruckerPrager::new(e, 30.0, 0.0, 31.0).is_err());
        assert!(DruckerPrager::new(e, -1.0, 0.0, 0.0).is_err());
        assert!(DruckerPrager::new(e, 90.0, 0.0, 0.0).is_err());
        assert!(DruckerPrager::new(e, 30.0, -1.0, 0.0).is_err());
        assert!(DruckerPrager::new(e, 30.0, f64::NAN, 0.0).is_err());
        assert!(DruckerPrager::new(e, 0.0, 0.0, 0.0).is_err());
    }
}
