//! Innovation gates, one meaning for every aid source.
//!
//! Every gate yields a **test ratio**: the gate's statistic divided by its threshold, so a ratio
//! above 1 means rejected, whatever the aid, its dimension or the kind of gate. The ratio is
//! recorded in the aid diagnostics (`AidDiagnosticsV1::test_ratio`), where residual analysis
//! reads it. Two kinds of gate are used:
//!
//! * **χ² on the normalised innovation squared** (NIS = yᵀ S⁻¹ y), for DVL, depth, GNSS and
//!   zero-velocity updates: ratio = NIS / threshold.
//! * **Per component** (ε_i² / S_ii against a χ²₁ threshold, the largest component decides), for
//!   the adaptive USBL filters, whose noise is learnt per component: ratio = max_i(ε_i² / S_ii) /
//!   threshold.
//!
//! A ratio that is not a number (a NaN innovation) is rejected.

/// χ² gate, 1 degree of freedom, 99.9 %.
pub const CHI2_1DOF_999: f64 = 10.83;
/// χ² gate, 3 degrees of freedom, 99.9 %.
pub const CHI2_3DOF_999: f64 = 16.27;

/// The outcome of a gate.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GateOutcome {
    /// Statistic / threshold: above 1 = rejected.
    pub test_ratio: f64,
    /// The measurement passed the gate.
    pub passed: bool,
}

/// The χ² gate on the normalised innovation squared `nis` at `threshold`.
pub fn nis(nis: f64, threshold: f64) -> GateOutcome {
    GateOutcome {
        test_ratio: nis / threshold,
        passed: nis <= threshold,
    }
}

/// The per-component gate: innovation `eps[i]` with variance `s(i)` against the χ²₁ value
/// `threshold`; one component outside rejects the whole measurement.
pub fn per_component(eps: &[f64], s: impl Fn(usize) -> f64, threshold: f64) -> GateOutcome {
    let mut worst: f64 = 0.0;
    let mut passed = true;
    for (i, e) in eps.iter().enumerate() {
        let si = s(i);
        let e2 = e * e;
        if e2.is_nan() || e2 > threshold * si {
            passed = false;
        }
        let r = e2 / si;
        worst = if r.is_nan() { f64::NAN } else { worst.max(r) };
        if worst.is_nan() {
            break;
        }
    }
    GateOutcome {
        test_ratio: if worst.is_nan() {
            f64::INFINITY
        } else {
            worst / threshold
        },
        passed,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ratio_above_one_means_rejected_for_both_kinds() {
        for (x, pass) in [(5.0, true), (10.83, true), (10.9, false), (100.0, false)] {
            let g = nis(x, CHI2_1DOF_999);
            assert_eq!(g.passed, pass);
            assert_eq!(g.test_ratio > 1.0, !pass, "nis {x}");
            let c = per_component(&[x.sqrt(), 0.1], |_| 1.0, CHI2_1DOF_999);
            assert_eq!(c.passed, pass);
            assert_eq!(c.test_ratio > 1.0, !pass, "component {x}");
        }
        let nan = per_component(&[f64::NAN, 0.0], |_| 1.0, CHI2_1DOF_999);
        assert!(!nan.passed && nan.test_ratio > 1.0);
    }
}
