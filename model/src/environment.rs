//! Air refractive index (Ciddor 1996; modified Edlen as in NIST's Engineering Metrology Toolbox)
//! and ISO 1 normalisation of machine scales to 20 degC.
//!
//! An interferometer counts fringes of the wavelength in air, `lambda_vac / n`. When a campaign
//! declares its readings uncompensated, they were computed with an assumed index `n0` (often 1,
//! i.e. vacuum wavelengths), and the true length is `l_raw * n0 / n(t, p, RH)`.

/// Which air-index equation to use.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "serde", serde(rename_all = "snake_case"))]
pub enum AirIndexEquation {
    /// Ciddor (1996), valid 300-1690 nm, -40..100 degC.
    #[default]
    Ciddor,
    /// Edlen (1966) as updated by Birch & Downs and modified by NIST for the water vapour term.
    Edlen,
}

/// State of the air along the beam.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct Air {
    pub temp_c: f64,
    pub pressure_pa: f64,
    pub humidity_pct: f64,
    pub co2_ppm: f64,
}

impl Air {
    /// Reference laboratory air: 20 degC, 101325 Pa, 50 % RH, 450 ppm CO2.
    pub fn standard() -> Air {
        Air { temp_c: 20.0, pressure_pa: 101_325.0, humidity_pct: 50.0, co2_ppm: 450.0 }
    }

    /// Checks the ranges in which the equations are valid.
    pub fn validate(&self) -> Result<(), String> {
        if !(self.temp_c.is_finite() && (-40.0..=100.0).contains(&self.temp_c)) {
            return Err(format!("air temperature {} degC outside -40..100", self.temp_c));
        }
        if !(self.pressure_pa.is_finite() && (10_000.0..=140_000.0).contains(&self.pressure_pa)) {
            return Err(format!("air pressure {} Pa outside 10 kPa..140 kPa (is it in hPa or kPa?)", self.pressure_pa));
        }
        if !(self.humidity_pct.is_finite() && (0.0..=100.0).contains(&self.humidity_pct)) {
            return Err(format!("relative humidity {} % outside 0..100", self.humidity_pct));
        }
        Ok(())
    }
}

/// Saturation vapour pressure over water (IAPWS 1997), Pa, for `t` in degC (t >= 0); over ice
/// below 0 degC (IAPWS 2011 simplified, as in the NIST toolbox).
pub fn saturation_vapour_pressure(t_c: f64) -> f64 {
    let t = t_c + 273.15;
    if t_c >= 0.0 {
        const K: [f64; 10] = [
            1.167_052_145_28e3,
            -7.242_131_670_32e5,
            -1.707_384_694_01e1,
            1.202_082_470_25e4,
            -3.232_555_032_23e6,
            1.491_510_861_35e1,
            -4.823_265_736_16e3,
            4.051_134_054_21e5,
            -2.385_555_756_78e-1,
            6.501_753_484_48e2,
        ];
        let omega = t + K[8] / (t - K[9]);
        let a = omega * omega + K[0] * omega + K[1];
        let b = K[2] * omega * omega + K[3] * omega + K[4];
        let c = K[5] * omega * omega + K[6] * omega + K[7];
        let x = -b + (b * b - 4.0 * a * c).sqrt();
        1e6 * (2.0 * c / x).powi(4)
    } else {
        const A1: f64 = -13.928_169;
        const A2: f64 = 34.707_823_8;
        let theta = t / 273.16;
        let y = A1 * (1.0 - theta.powf(-1.5)) + A2 * (1.0 - theta.powf(-1.25));
        611.657 * y.exp()
    }
}

/// Refractive index of moist air, Ciddor (1996), for vacuum wavelength `lambda_vac_m`.
pub fn ciddor(lambda_vac_m: f64, air: &Air) -> f64 {
    let t = air.temp_c;
    let p = air.pressure_pa;
    let tk = t + 273.15;
    let s = 1.0 / (lambda_vac_m * 1e6).powi(2);
    let (w0, w1, w2, w3) = (295.235, 2.6422, -0.032380, 0.004028);
    let (k0, k1, k2, k3) = (238.0185, 5_792_105.0, 57.362, 167_917.0);
    let (a0, a1, a2) = (1.58123e-6, -2.9331e-8, 1.1043e-10);
    let (b0, b1) = (5.707e-6, -2.051e-8);
    let (c0, c1) = (1.9898e-4, -2.376e-6);
    let (d, e) = (1.83e-11, -0.765e-8);
    let (p_r1, t_r1, z_a, rho_vs, r, m_v) = (101_325.0, 288.15, 0.999_592_211_5, 0.009_859_38, 8.314_472, 0.018_015);

    let r_as = 1e-8 * (k1 / (k0 - s) + k3 / (k2 - s));
    let r_vs = 1.022e-8 * (w0 + w1 * s + w2 * s * s + w3 * s * s * s);
    let m_a = 0.028_963_5 + 1.2011e-8 * (air.co2_ppm - 400.0);
    let r_axs = r_as * (1.0 + 5.34e-7 * (air.co2_ppm - 450.0));
    let f = 1.000_62 + 3.14e-8 * p + 5.6e-7 * t * t;
    let x_w = f * air.humidity_pct / 100.0 * saturation_vapour_pressure(t) / p;
    let z = 1.0 - (p / tk) * (a0 + a1 * t + a2 * t * t + (b0 + b1 * t) * x_w + (c0 + c1 * t) * x_w * x_w)
        + (p / tk).powi(2) * (d + e * x_w * x_w);
    let rho_axs = p_r1 * m_a / (z_a * r * t_r1);
    let rho_v = x_w * p * m_v / (z * r * tk);
    let rho_a = (1.0 - x_w) * p * m_a / (z * r * tk);
    1.0 + (rho_a / rho_axs) * r_axs + (rho_v / rho_vs) * r_vs
}

/// Refractive index of moist air, modified Edlen equation (NIST), for `lambda_vac_m`.
/// Assumes 450 ppm CO2.
pub fn edlen(lambda_vac_m: f64, air: &Air) -> f64 {
    let t = air.temp_c;
    let p = air.pressure_pa;
    let s = 1.0 / (lambda_vac_m * 1e6).powi(2);
    let ns1 = 1e-8 * (8342.54 + 2_406_147.0 / (130.0 - s) + 15_998.0 / (38.9 - s));
    let x = (1.0 + 1e-8 * (0.601 - 0.009_72 * t) * p) / (1.0 + 0.003_661 * t);
    let ntp1 = p * ns1 * x / 96_095.43;
    let pv = air.humidity_pct / 100.0 * saturation_vapour_pressure(t);
    1.0 + ntp1 - 1e-10 * (292.75 / (t + 273.15)) * (3.7345 - 0.0401 * s) * pv
}

/// Refractive index by the chosen equation.
pub fn air_index(eq: AirIndexEquation, lambda_vac_m: f64, air: &Air) -> f64 {
    match eq {
        AirIndexEquation::Ciddor => ciddor(lambda_vac_m, air),
        AirIndexEquation::Edlen => edlen(lambda_vac_m, air),
    }
}

/// Factor that turns an uncompensated reading (made with assumed index `n_assumed`) into a
/// length: `l_true = factor * l_raw`.
pub fn compensation_factor(n_assumed: f64, n_actual: f64) -> f64 {
    n_assumed / n_actual
}

/// ISO 1 normalisation: the indicated coordinate of a scale with expansion coefficient `alpha`
/// (1/K) at temperature `temp_c`, measured from the scale's fixed point `fixed_m`, expressed as
/// the length it represents at 20 degC.
pub fn normalise_to_20c(q: f64, alpha: f64, temp_c: f64, fixed_m: f64) -> f64 {
    fixed_m + (q - fixed_m) * (1.0 + alpha * (temp_c - 20.0))
}

#[cfg(test)]
mod tests {
    use super::*;

    // Reference values: the `ref_index` module (P. Nair), which implements the NIST Engineering
    // Metrology Toolbox equations, 633 nm vacuum wavelength, 101325 Pa, 450 ppm CO2.
    fn air(t: f64, rh: f64) -> Air {
        Air { temp_c: t, pressure_pa: 101_325.0, humidity_pct: rh, co2_ppm: 450.0 }
    }

    #[test]
    fn ciddor_matches_reference() {
        let cases = [
            (20.0, 20.0, 1.000_271_628_534_057_8),
            (20.0, 80.0, 1.000_271_118_347_262_6),
            (60.0, 80.0, 1.000_234_024_175_405_5),
        ];
        for (t, rh, n) in cases {
            let got = ciddor(633e-9, &air(t, rh));
            assert!((got - n).abs() < 2e-12, "t={t} rh={rh}: {got} vs {n}");
        }
    }

    #[test]
    fn edlen_matches_reference() {
        let cases = [
            (20.0, 20.0, 1.000_271_629_169_164_9),
            (20.0, 80.0, 1.000_271_119_763_522_6),
            (60.0, 80.0, 1.000_233_974_854_282_3),
        ];
        for (t, rh, n) in cases {
            let got = edlen(633e-9, &air(t, rh));
            assert!((got - n).abs() < 2e-12, "t={t} rh={rh}: {got} vs {n}");
        }
    }

    #[test]
    fn sensitivity_is_about_one_ppm_per_kelvin() {
        let a = ciddor(633e-9, &air(20.0, 50.0));
        let b = ciddor(633e-9, &air(21.0, 50.0));
        assert!(((a - b) * 1e6 - 0.93).abs() < 0.05, "{}", (a - b) * 1e6);
    }
}
