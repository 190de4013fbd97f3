//! The gyro as a source of the hard iron (the rotation constraint, as MAGYC uses it).
//!
//! The Earth's field is fixed in the world, so in the sensor's axes it turns against the
//! vehicle's rotation: `Ḃ = −ω × B`. With the hard iron `b` and one scale, `h = B/s + b`, so
//! between two readings `ḣ = −(ω − β) × (h − b)`, with β the gyro's bias. Written out,
//!
//! `ḣ + ω × h = ω × b + β × h − β × b`,
//!
//! which is linear in `b`, `β` and `c = β × b` taken as nine unknowns (MAGYC's least-squares
//! form). It needs no accelerometer and no field magnitude: a vehicle turning about its vertical
//! alone gives the horizontal hard iron, roll and pitch give the vertical; its accuracy is that of
//! the gyro and of the readings' differences. The scale comes from the field's magnitude
//! afterwards. `ḣ` is the difference of consecutive readings over their interval and `ω` the
//! sample's mean rate over the same interval ([`MagSample::angular_rate`]); intervals longer
//! than five times the median (gaps, a new recording) are left out.

use super::fit::{Calibration, FitError, MagSample};
use nalgebra::{Matrix3, SMatrix, SVector, Vector3};

/// Fewest usable intervals for the fit.
const MIN_INTERVALS: usize = 30;

fn skew(v: &Vector3<f64>) -> Matrix3<f64> {
    Matrix3::new(0.0, -v.z, v.y, v.z, 0.0, -v.x, -v.y, v.x, 0.0)
}

/// Whether most samples carry an angular rate.
pub fn has_rates(samples: &[MagSample]) -> bool {
    2 * samples.iter().filter(|s| s.angular_rate.is_some()).count() > samples.len()
}

/// The hard iron (and one scale to `field_ut`) from the rotation constraint, with the gyro's bias
/// estimated beside it.
pub fn hard_iron(samples: &[MagSample], field_ut: f64) -> Result<Calibration, FitError> {
    let Some(dt) = super::fit::median_interval(samples) else {
        return Err(FitError::Degenerate("no time between the readings".into()));
    };
    let limit = 5.0 * dt;
    let mut ata = SMatrix::<f64, 9, 9>::zeros();
    let mut aty = SVector::<f64, 9>::zeros();
    let mut used = 0usize;
    let mut turned = 0.0;
    for w in samples.windows(2) {
        let dt = w[1].time_s - w[0].time_s;
        let Some(rate) = w[1].angular_rate else {
            continue;
        };
        if !(dt > 0.0 && dt <= limit) {
            continue;
        }
        let h = 0.5 * (w[0].field_ut + w[1].field_ut);
        let y = (w[1].field_ut - w[0].field_ut) / dt + rate.cross(&h);
        // y = [ω]× b − [h]× β − c.
        let mut a = SMatrix::<f64, 3, 9>::zeros();
        a.fixed_view_mut::<3, 3>(0, 0).copy_from(&skew(&rate));
        a.fixed_view_mut::<3, 3>(0, 3).copy_from(&(-skew(&h)));
        a.fixed_view_mut::<3, 3>(0, 6)
            .copy_from(&(-Matrix3::identity()));
        ata += a.transpose() * a;
        aty += a.transpose() * y;
        used += 1;
        turned += rate.norm() * dt;
    }
    if used < MIN_INTERVALS {
        return Err(FitError::Degenerate(format!(
            "{used} intervals with an angular rate (at least {MIN_INTERVALS}): the rotation \
             constraint needs the gyro"
        )));
    }
    let svd = ata.svd(true, true);
    let (smax, smin) = (svd.singular_values.max(), svd.singular_values.min());
    if smin.is_nan() || smin <= 1e-12 * smax {
        return Err(FitError::Degenerate(format!(
            "the rotations ({:.0}° in all) do not determine the hard iron and the gyro bias: \
             turn about more than one axis",
            turned.to_degrees()
        )));
    }
    let x = svd
        .solve(&aty, 0.0)
        .map_err(|e| FitError::Degenerate(format!("the rotation constraint: {e}")))?;
    let b = Vector3::new(x[0], x[1], x[2]);
    let n = samples.len() as f64;
    let mean_norm = samples.iter().map(|s| (s.field_ut - b).norm()).sum::<f64>() / n;
    if !(mean_norm > 0.0 && b.iter().all(|v| v.is_finite())) {
        return Err(FitError::Degenerate(
            "the rotation constraint gives no finite hard iron".into(),
        ));
    }
    Ok(Calibration {
        k: Matrix3::identity() * (field_ut / mean_norm),
        hard_iron_ut: b,
        lambda: None,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_tumbling_sensor_gives_its_hard_iron_and_a_biased_gyro_does_not_fool_it() {
        let field = Vector3::new(20.0, 1.0, 44.0);
        let b = Vector3::new(6.0, -4.0, 9.0);
        let bias = Vector3::new(0.004, -0.003, 0.002);
        let dt = 0.02;
        let mut r = nalgebra::Rotation3::identity();
        let mut s = Vec::new();
        for i in 0..5000 {
            let t = i as f64 * dt;
            let w = Vector3::new(0.3 * (0.2 * t).sin(), 0.25 * (0.13 * t).cos(), 0.4);
            // Body rotation over the step; the field in body axes turns the other way.
            r *= nalgebra::Rotation3::new(w * dt);
            let body = r.inverse() * field;
            s.push(MagSample {
                time_s: t,
                field_ut: body + b,
                specific_force: None,
                angular_rate: Some(w + bias),
                truth_rpy: None,
            });
        }
        let c = hard_iron(&s, field.norm()).expect("fit");
        assert!((c.hard_iron_ut - b).norm() < 0.05, "{:?}", c.hard_iron_ut);
        // Without a rate there is nothing to fit.
        let none: Vec<MagSample> = s
            .iter()
            .map(|x| MagSample {
                angular_rate: None,
                ..*x
            })
            .collect();
        assert!(hard_iron(&none, 50.0).is_err());
    }
}
