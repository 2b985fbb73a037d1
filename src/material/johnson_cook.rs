//! J2 plasticity with Johnson–Cook hardening and Johnson–Cook damage, for metals under impact,
//! with an optional Mie–Grüneisen equation of state.
//!
//! Same kinematics as Drucker–Prager (`F = F_e F_p`, Hencky elasticity, predictor
//! `F_e^tr = ΔF F_e^n`, return in principal logarithmic strain). The flow is isochoric, so the
//! pressure is a function of `J = det F` alone: Hencky's `p = −K ln J`, or the Mie–Grüneisen
//! equation of state when one is given. The deviatoric Kirchhoff stress is `2 G dev ε_e`.
//!
//! * Yield stress (Johnson & Cook 1983): `σ_y = (A + B ε̄ⁿ)(1 + C ln ε̇*)(1 − T*ᵐ)` with
//!   `ε̇* = max(ε̇/ε̇0, 1)` and `T* = (T − T_room)/(T_melt − T_room)`; the plastic strain increment
//!   of a step solves `q^tr − 3 G Δε̄ = σ_y(ε̄ + Δε̄, Δε̄/Δt, T)` (safeguarded Newton).
//! * Heating: adiabatic, `ΔT = χ σ_y Δε̄ / (ρ0 c_p)` (Taylor–Quinney `χ`), applied after the step.
//! * Damage (Johnson & Cook 1985): `D += Δε̄ / ε_f`,
//!   `ε_f = [D1 + D2 exp(D3 σ*)][1 + D4 ln ε̇*][1 + D5 T*]`, `σ* = −p / σ_eq` (triaxiality).
//!   Damage does not soften the material before failure (uncoupled). **At failure (`D = 1`)** the
//!   point carries no deviatoric stress and no tension: its stress becomes `−max(p, 0) I`, and it
//!   stays failed. A melted point (`T ≥ T_melt`) likewise has no strength.
//! * Mesh regularization (optional, by the caller): the failure band cannot be narrower than
//!   about a cell, so on coarse cells the strains to failure can be scaled down
//!   ([`JohnsonCookParameters::regularized`], a crack band).

use super::plastic::History;
use super::ElasticConstants;
use crate::error::{check_finite, check_positive, Error, Result};
use nalgebra::{Matrix3, Vector3};

/// Mie–Grüneisen equation of state with a linear `U_s = c0 + s u_p` Hugoniot:
/// with `μ = ρ/ρ0 − 1 = 1/J − 1` and `e` the internal energy per unit reference volume,
/// `p = ρ0 c0² μ [1 + (1 − Γ0/2) μ] / [1 − (s − 1) μ]² + Γ0 e` in compression and
/// `p = ρ0 c0² μ + Γ0 e` in tension.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MieGruneisen {
    pub sound_speed: f64,
    pub slope: f64,
    pub gamma0: f64,
}

impl MieGruneisen {
    /// Pressure at volume ratio `j` and internal energy `e` per unit reference volume.
    pub fn pressure(&self, rho0: f64, j: f64, e: f64) -> f64 {
        let mu = 1.0 / j - 1.0;
        let k0 = rho0 * self.sound_speed * self.sound_speed;
        if mu > 0.0 {
            let d = 1.0 - (self.slope - 1.0) * mu;
            k0 * mu * (1.0 + (1.0 - 0.5 * self.gamma0) * mu) / (d * d) + self.gamma0 * e
        } else {
            k0 * mu + self.gamma0 * e
        }
    }
}

/// Johnson–Cook parameters as a caller gives them (SI units, temperatures in kelvin).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct JohnsonCookParameters {
    pub density: f64,
    pub young: f64,
    pub poisson: f64,
    /// `A`, `B`, `n`: strain hardening.
    pub a: f64,
    pub b: f64,
    pub n: f64,
    /// `C` and `ε̇0`: rate term.
    pub c: f64,
    pub reference_strain_rate: f64,
    /// `m`, `T_room`, `T_melt`: thermal softening.
    pub m: f64,
    pub room_temperature: f64,
    pub melt_temperature: f64,
    /// `c_p` (J/(kg K)) and Taylor–Quinney `χ` (0 disables heating).
    pub specific_heat: f64,
    pub taylor_quinney: f64,
    /// `D1 … D5`; `None` disables damage.
    pub damage: Option<[f64; 5]>,
    /// Mie–Grüneisen EOS; `None` uses Hencky's `p = −K ln J`.
    pub eos: Option<MieGruneisen>,
}

impl JohnsonCookParameters {
    /// Crack-band regularization of the damage for cells of `cell_size`: the strain to failure
    /// `(D1 + D2 exp(D3 σ*))(1 + D4 ln ε̇*)(1 + D5 T*)` is scaled by `band_width / cell_size`
    /// when the cells are coarser than `band_width`, the width of the failure band the
    /// constants describe (unchanged on finer cells). A shear band cannot be narrower than
    /// about a cell, so on coarse cells it is that many times wider than the real one; failing
    /// it at a proportionally smaller strain keeps the work spent per unit area of the crack
    /// (width × strain to failure) about independent of the cells, as Bažant's crack band does
    /// for softening and finite-element codes' element-size regularization of failure strains
    /// does for ductile failure. Scales `D1` and `D2`; without damage it changes nothing. A C
    /// or Fortran caller does the same by scaling `d1` and `d2`.
    pub fn regularized(mut self, band_width: f64, cell_size: f64) -> Result<Self> {
        check_positive("band_width", band_width)?;
        check_positive("cell_size", cell_size)?;
        if let Some(d) = &mut self.damage {
            let scale = (band_width / cell_size).min(1.0);
            d[0] *= scale;
            d[1] *= scale;
        }
        Ok(self)
    }
}

/// OFHC copper: Johnson–Cook strength (Johnson & Cook 1983) and damage (Johnson & Cook 1985)
/// constants, and the Mie–Grüneisen EOS of copper (c0 = 3940 m/s, s = 1.49, Γ0 = 1.96).
pub fn ofhc_copper() -> JohnsonCookParameters {
    JohnsonCookParameters {
        density: 8960.0,
        young: 124e9,
        poisson: 0.34,
        a: 90e6,
        b: 292e6,
        n: 0.31,
        c: 0.025,
        reference_strain_rate: 1.0,
        m: 1.09,
        room_temperature: 298.0,
        melt_temperature: 1356.0,
        specific_heat: 383.0,
        taylor_quinney: 0.9,
        damage: Some([0.54, 4.89, -3.03, 0.014, 1.12]),
        eos: Some(MieGruneisen {
            sound_speed: 3940.0,
            slope: 1.49,
            gamma0: 1.96,
        }),
    }
}

/// J2 plasticity with Johnson–Cook hardening, damage and (optionally) Mie–Grüneisen pressure.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct JohnsonCook {
    pub elastic: ElasticConstants,
    pub p: JohnsonCookParameters,
}

impl JohnsonCook {
    /// Checks the parameters: positive density, moduli, `A`, `ε̇0`, `c_p`, `T_melt > T_room`,
    /// `B, n, C, m ≥ 0`, `0 ≤ χ ≤ 1`, EOS `c0 > 0`, `s ≥ 1`, `Γ0 ≥ 0`, all finite.
    pub fn new(p: JohnsonCookParameters) -> Result<Self> {
        let elastic = ElasticConstants::new(p.density, p.young, p.poisson)?;
        check_positive("A", p.a)?;
        check_positive("reference_strain_rate", p.reference_strain_rate)?;
        check_positive("specific_heat", p.specific_heat)?;
        check_positive("room_temperature", p.room_temperature)?;
        for (name, v) in [("B", p.b), ("n", p.n), ("C", p.c), ("m", p.m)] {
            check_finite(name, v)?;
            if v < 0.0 {
                return Err(Error::invalid(format!("{name} must be >= 0, got {v}")));
            }
        }
        check_finite("melt_temperature", p.melt_temperature)?;
        if p.melt_temperature <= p.room_temperature {
            return Err(Error::invalid(format!(
                "melt_temperature ({}) must exceed room_temperature ({})",
                p.melt_temperature, p.room_temperature
            )));
        }
        check_finite("taylor_quinney", p.taylor_quinney)?;
        if !(0.0..=1.0).contains(&p.taylor_quinney) {
            return Err(Error::invalid(format!(
                "taylor_quinney must lie in [0, 1], got {}",
                p.taylor_quinney
            )));
        }
        if let Some(d) = p.damage {
            for (k, v) in d.iter().enumerate() {
                check_finite(&format!("D{}", k + 1), *v)?;
            }
        }
        if let Some(e) = p.eos {
            check_positive("eos_sound_speed", e.sound_speed)?;
            check_finite("eos_slope", e.slope)?;
            check_finite("eos_gamma0", e.gamma0)?;
            if e.slope < 1.0 || e.gamma0 < 0.0 {
                return Err(Error::invalid(format!(
                    "eos_slope must be >= 1 and eos_gamma0 >= 0, got {} and {}",
                    e.slope, e.gamma0
                )));
            }
        }
        let model = JohnsonCook { elastic, p };
        // The EOS's bulk modulus `ρ0 c0²` may exceed the elastic one: the wave speed the
        // stable step uses, at the reference volume.
        super::check_physical(p.density, model.wave_speed(1.0))?;
        Ok(model)
    }

    fn homologous(&self, heating: f64) -> f64 {
        (heating / (self.p.melt_temperature - self.p.room_temperature)).max(0.0)
    }

    /// Yield stress at plastic strain `eps`, plastic strain rate `rate` and temperature rise
    /// `heating` above room temperature.
    pub fn yield_stress(&self, eps: f64, rate: f64, heating: f64) -> f64 {
        let p = &self.p;
        let t = self.homologous(heating);
        if t >= 1.0 {
            return 0.0;
        }
        let rate_term = 1.0 + p.c * (rate / p.reference_strain_rate).max(1.0).ln();
        (p.a + p.b * eps.max(0.0).powf(p.n)) * rate_term * (1.0 - t.powf(p.m))
    }

    /// Pressure (positive in compression) at volume ratio `j` and temperature rise `heating`.
    pub fn pressure(&self, j: f64, heating: f64) -> f64 {
        match self.p.eos {
            Some(eos) => {
                let e = self.p.density * self.p.specific_heat * heating;
                eos.pressure(self.p.density, j, e)
            }
            None => -(self.elastic.lambda + 2.0 / 3.0 * self.elastic.mu) * j.ln() / j,
        }
    }

    /// Bulk modulus `−J dp/dJ` at `j` (central difference of the pressure; for the time step).
    pub fn bulk_modulus(&self, j: f64) -> f64 {
        let d = 1e-6 * j;
        -j * (self.pressure(j + d, 0.0) - self.pressure(j - d, 0.0)) / (2.0 * d)
    }

    /// Plastic strain increment of a step: solves `q − 3 G Δ = σ_y(ε̄ + Δ, Δ/dt, T)` for `Δ` in
    /// `[0, q/(3G)]`, where the left side falls and the right side rises with `Δ` (bisection
    /// safeguards Newton with a finite-difference slope).
    fn plastic_increment(&self, q: f64, eps: f64, dt: f64, heating: f64) -> f64 {
        let g = self.elastic.mu;
        let residual = |d: f64| q - 3.0 * g * d - self.yield_stress(eps + d, d / dt, heating);
        let (mut lo, mut hi) = (0.0, q / (3.0 * g));
        let mut d = 0.5 * hi;
        for _ in 0..100 {
            let r = residual(d);
            if r.abs() <= 1e-12 * q {
                break;
            }
            if r > 0.0 {
                lo = d;
            } else {
                hi = d;
            }
            let h = 1e-8 * hi.max(1e-12);
            let slope = (residual(d + h) - r) / h;
            let newton = d - r / slope;
            d = if slope < 0.0 && newton > lo && newton < hi {
                newton
            } else {
                0.5 * (lo + hi)
            };
            if hi - lo <= 1e-15 * hi {
                break;
            }
        }
        d
    }

    /// One constitutive update over `dt`: new state and Cauchy stress after the increment `df`,
    /// for a total `det F = j`.
    pub fn update(
        &self,
        state: &History,
        df: &Matrix3<f64>,
        j: f64,
        dt: f64,
    ) -> (History, Matrix3<f64>) {
        let g = self.elastic.mu;
        let fe = df * state.elastic_deformation;
        let svd = fe.svd(true, true);
        let (u, vt) = (svd.u.expect("U"), svd.v_t.expect("Vᵀ"));
        let eps = svd.singular_values.map(|s| s.ln());
        let vol = eps.sum() / 3.0;
        let dev = eps - Vector3::repeat(vol);
        let s_trial = 2.0 * g * dev;
        let q = (1.5 * s_trial.norm_squared()).sqrt();
        let mut next = *state;
        let failed = state.damage >= 1.0 || self.homologous(state.heating) >= 1.0;
        let sigma_y = self.yield_stress(state.plastic_strain, 0.0, state.heating);
        let (dev_new, s_new) = if failed {
            // No deviatoric stress: the whole deviatoric strain increment is plastic.
            let d = (2.0f64 / 3.0).sqrt() * dev.norm();
            next.plastic_strain += d;
            (Vector3::zeros(), Vector3::zeros())
        } else if q <= sigma_y {
            (dev, s_trial)
        } else {
            let d = self.plastic_increment(q, state.plastic_strain, dt, state.heating);
            let scale = 1.0 - 3.0 * g * d / q;
            let flow_stress = q - 3.0 * g * d;
            next.plastic_strain += d;
            next.heating +=
                self.p.taylor_quinney * flow_stress * d / (self.p.density * self.p.specific_heat);
            (dev * scale, s_trial * scale)
        };
        let pressure = self.pressure(j, state.heating);
        if let (Some(dd), false) = (self.p.damage, failed) {
            let d_eps = next.plastic_strain - state.plastic_strain;
            if d_eps > 0.0 {
                let seq = (1.5 * s_new.norm_squared()).sqrt() / j;
                let triaxiality = if seq > 0.0 { -pressure / seq } else { 0.0 };
                let rate = (d_eps / dt / self.p.reference_strain_rate).max(1.0);
                let strain_to_failure = (dd[0] + dd[1] * (dd[2] * triaxiality).exp())
                    * (1.0 + dd[3] * rate.ln())
                    * (1.0 + dd[4] * self.homologous(state.heating));
                next.damage = if strain_to_failure > 0.0 {
                    (state.damage + d_eps / strain_to_failure).min(1.0)
                } else {
                    1.0
                };
            }
        }
        let fe_new =
            u * Matrix3::from_diagonal(&(dev_new + Vector3::repeat(vol)).map(f64::exp)) * vt;
        next.elastic_deformation = fe_new;
        let sigma = if next.damage >= 1.0 {
            Matrix3::identity() * -pressure.max(0.0)
        } else {
            u * Matrix3::from_diagonal(&(s_new / j)) * u.transpose()
                - Matrix3::identity() * pressure
        };
        (next, sigma)
    }

    /// P-wave speed at `j` from the EOS bulk modulus (or Hencky's) and the shear modulus.
    pub fn wave_speed(&self, j: f64) -> f64 {
        let k = self
            .bulk_modulus(j)
            .max(self.elastic.lambda + 2.0 / 3.0 * self.elastic.mu);
        ((k + 4.0 / 3.0 * self.elastic.mu) * j / self.elastic.density).sqrt()
    }

    /// Stored energy per unit reference volume of a point in state `state`: the elastic energy
    /// of `F_e`, or for a failed (or melted) point, which carries no deviator and no tension,
    /// only the bulk energy of compression.
    pub fn stored_energy(&self, state: &History) -> f64 {
        let fe = &state.elastic_deformation;
        if state.damage >= 1.0 || self.homologous(state.heating) >= 1.0 {
            let vol = fe.determinant().ln();
            let k = self.elastic.lambda + 2.0 / 3.0 * self.elastic.mu;
            return if vol < 0.0 { 0.5 * k * vol * vol } else { 0.0 };
        }
        self.elastic_energy(fe)
    }

    /// Elastic energy per unit reference volume of `F_e` (Hencky shear part plus the bulk part of
    /// Hencky's law; the EOS energy is not included).
    pub fn elastic_energy(&self, fe: &Matrix3<f64>) -> f64 {
        let eps = fe.svd(false, false).singular_values.map(|s| s.ln());
        let vol = eps.sum();
        let dev = eps - Vector3::repeat(vol / 3.0);
        0.5 * (self.elastic.lambda + 2.0 / 3.0 * self.elastic.mu) * vol * vol
            + self.elastic.mu * dev.norm_squared()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// OFHC copper with or without damage and EOS.
    pub fn copper(damage: bool, eos: bool) -> JohnsonCook {
        let p = ofhc_copper();
        JohnsonCook::new(JohnsonCookParameters {
            damage: p.damage.filter(|_| damage),
            eos: p.eos.filter(|_| eos),
            ..p
        })
        .unwrap()
    }

    fn stretch(e: f64) -> Matrix3<f64> {
        // Isochoric uniaxial stretch: diag(exp(e), exp(−e/2), exp(−e/2)).
        Matrix3::from_diagonal(&Vector3::new(e.exp(), (-0.5 * e).exp(), (-0.5 * e).exp()))
    }

    /// Isochoric uniaxial tension, quasi-static (rate term off below ε̇0), no heating: after the
    /// return the equivalent stress equals `A + B ε̄ⁿ` at the accumulated plastic strain, and the
    /// plastic strain equals the total strain minus the elastic part `σ_y / E_shear-equivalent`.
    #[test]
    fn uniaxial_stress_follows_the_hardening_curve() {
        let mut cu = copper(false, false);
        cu.p.taylor_quinney = 0.0;
        let mut state = History::default();
        let mut sigma = Matrix3::zeros();
        let steps = 200;
        let total = 0.2;
        for _ in 0..steps {
            (state, sigma) = cu.update(&state, &stretch(total / steps as f64), 1.0, 1.0);
        }
        let s = sigma - Matrix3::identity() * (sigma.trace() / 3.0);
        let seq = (1.5 * s.norm_squared()).sqrt();
        let expected = cu.yield_stress(state.plastic_strain, 0.0, 0.0);
        assert!(
            (seq - expected).abs() < 1e-9 * expected,
            "{seq} vs {expected}"
        );
        // Total equivalent strain = plastic + elastic (σ_eq / 3G).
        let elastic = seq / (3.0 * cu.elastic.mu);
        assert!(
            (state.plastic_strain + elastic - total).abs() < 1e-9,
            "{state:?}"
        );
        assert!(sigma.trace().abs() < 1e-6 * seq, "isochoric: no pressure");
    }

    /// A faster step (same strain, shorter dt) gives a higher flow stress by the rate term.
    #[test]
    fn rate_and_temperature_terms() {
        let cu = copper(false, false);
        assert!((cu.yield_stress(0.0, 0.5, 0.0) - 90e6).abs() < 1e-6);
        let fast = cu.yield_stress(0.1, 1e4, 0.0);
        let slow = cu.yield_stress(0.1, 1.0, 0.0);
        assert!((fast / slow - (1.0 + 0.025 * 1e4f64.ln())).abs() < 1e-12);
        let hot = cu.yield_stress(0.1, 1.0, 0.5 * (1356.0 - 298.0));
        assert!((hot / slow - (1.0 - 0.5f64.powf(1.09))).abs() < 1e-12);
        assert_eq!(cu.yield_stress(0.1, 1.0, 2000.0), 0.0);
    }

    /// Heating from plastic work: ΔT = χ σ_y Δε̄ / (ρ c_p) summed over the steps.
    #[test]
    fn adiabatic_heating_matches_plastic_work() {
        let cu = copper(false, false);
        let mut state = History::default();
        let mut work = 0.0;
        for _ in 0..100 {
            let before = state;
            let (next, sigma) = cu.update(&state, &stretch(0.002), 1.0, 1e-6);
            let s = sigma - Matrix3::identity() * (sigma.trace() / 3.0);
            work += (1.5 * s.norm_squared()).sqrt() * (next.plastic_strain - before.plastic_strain);
            state = next;
        }
        let expected = 0.9 * work / (8960.0 * 383.0);
        assert!(
            (state.heating - expected).abs() < 1e-9 * expected,
            "{} vs {expected}",
            state.heating
        );
    }

    /// Damage grows as Δε̄/ε_f; at D = 1 the point keeps only compressive pressure. Isochoric
    /// stretching has zero pressure (triaxiality 0) and, without heating, a constant
    /// `ε_f = (D1 + D2)(1 + D4 ln ε̇*)`: failure comes at that plastic strain, to one step.
    #[test]
    fn damage_accumulates_and_failure_releases_stress() {
        let mut cu = copper(true, false);
        cu.p.taylor_quinney = 0.0;
        let mut state = History::default();
        let mut n = 0;
        while state.damage < 1.0 && n < 10_000 {
            state = cu.update(&state, &stretch(0.01), 1.0, 1e-6).0;
            n += 1;
        }
        assert!(state.damage == 1.0, "never failed");
        let ef = (0.54 + 4.89) * (1.0 + 0.014 * (1e4f64).ln());
        assert!(
            (state.plastic_strain - ef).abs() < 0.011,
            "{} vs {ef}",
            state.plastic_strain
        );
        // Failed: tension gives no stress, compression gives pressure only.
        let (_, s) = cu.update(&state, &stretch(0.01), 1.02, 1e-6);
        assert_eq!(s, Matrix3::zeros());
        let (_, s) = cu.update(&state, &stretch(0.01), 0.98, 1e-6);
        assert!((s - Matrix3::identity() * s[(0, 0)]).norm() == 0.0 && s[(0, 0)] < 0.0);
    }

    /// Crack-band regularization: on cells twice the band the point fails at half the strain
    /// (the same stretch history, so the same triaxiality and rate), on finer cells at the
    /// same strain; without damage nothing changes; bad widths are refused.
    #[test]
    fn regularization_scales_the_strain_to_failure() {
        let strain_at_failure = |p: JohnsonCookParameters| {
            let mut m = JohnsonCook::new(JohnsonCookParameters {
                taylor_quinney: 0.0,
                ..p
            })
            .unwrap();
            m.p.eos = None;
            let mut state = History::default();
            while state.damage < 1.0 {
                state = m.update(&state, &stretch(0.005), 1.0, 1e-6).0;
            }
            state.plastic_strain
        };
        let p = ofhc_copper();
        let full = strain_at_failure(p);
        let coarse = strain_at_failure(p.regularized(1e-3, 2e-3).unwrap());
        // One step's plastic strain (0.005) of slack on each side of the halved strain.
        assert!((coarse - full / 2.0).abs() < 0.006, "{coarse} vs {full}/2");
        assert_eq!(p.regularized(1e-3, 0.5e-3).unwrap(), p);
        let [d1, d2, d3, d4, d5] = p.damage.unwrap();
        assert_eq!(
            p.regularized(1e-3, 4e-3).unwrap().damage,
            Some([d1 / 4.0, d2 / 4.0, d3, d4, d5])
        );
        let undamaged = JohnsonCookParameters { damage: None, ..p };
        assert_eq!(undamaged.regularized(1e-3, 4e-3).unwrap(), undamaged);
        for (band, h) in [
            (0.0, 1e-3),
            (1e-3, -1.0),
            (f64::NAN, 1e-3),
            (1e-3, f64::INFINITY),
        ] {
            assert!(p.regularized(band, h).is_err(), "{band} {h}");
        }
    }

    /// Mie–Grüneisen: `p → ρ0 c0² μ` for small `μ`, and the Hugoniot stiffening in compression.
    #[test]
    fn mie_gruneisen_pressure() {
        let cu = copper(false, true);
        let k0 = 8960.0 * 3940.0f64.powi(2);
        let j = 1.0 - 1e-7;
        assert!((cu.pressure(j, 0.0) / (k0 * (1.0 / j - 1.0)) - 1.0).abs() < 1e-6);
        assert!(cu.pressure(0.8, 0.0) > k0 * 0.25);
        assert!(cu.pressure(1.01, 0.0) < 0.0);
        assert!(cu.wave_speed(0.9) > cu.wave_speed(1.0));
    }

    #[test]
    fn rejects_bad_parameters() {
        let good = copper(true, true).p;
        let bad = [
            JohnsonCookParameters { a: 0.0, ..good },
            JohnsonCookParameters { n: -1.0, ..good },
            JohnsonCookParameters {
                melt_temperature: 200.0,
                ..good
            },
            JohnsonCookParameters {
                taylor_quinney: 1.5,
                ..good
            },
            JohnsonCookParameters {
                damage: Some([f64::NAN, 0.0, 0.0, 0.0, 0.0]),
                ..good
            },
            JohnsonCookParameters {
                eos: Some(MieGruneisen {
                    sound_speed: 3940.0,
                    slope: 0.5,
                    gamma0: 2.0,
                }),
                ..good
            },
        ];
        for p in bad {
            assert!(JohnsonCook::new(p).is_err(), "{p:?}");
        }
    }
}
