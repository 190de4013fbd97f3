//! What discovery reports: the effects found and those it could not name, per channel and per
//! voyage, the detection floors, the noise and the navigation gain (the types of
//! `DiscoverReport`, apart from the code that fills them).

use super::ChannelKind;
use super::residuals::Description;
use auvnav_replay::accuracy::Accuracy;
use auvnav_sim::effects::Effects;
use serde::Serialize;

/// An effect discovery keeps.
#[derive(Debug, Clone, Serialize)]
pub struct FoundEffect {
    /// The effect's name in `auvnav sim --list-effects`.
    pub name: String,
    /// The estimate in the effect's unit (a number, or an array for a vector effect).
    pub value: serde_json::Value,
    /// One-sigma of the estimate (same shape; null where the motion does not determine it).
    pub std: serde_json::Value,
    /// The nominal model's value (the change found is `value` − `nominal`).
    pub nominal: serde_json::Value,
    pub unit: String,
    pub channel: ChannelKind,
    /// Why it was kept.
    pub evidence: String,
    /// Relative drop of the held-out mean squared residual when it was added.
    pub gain: f64,
    /// Another effect of the vocabulary that acts on the readings exactly as this one does, with
    /// the value that would explain the same change: the data cannot tell them apart, the
    /// engineer can (`dvl.scale_factor` and `dvl.sound_speed`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub equivalent: Option<Equivalent>,
    /// `dvl.periodic_velocity_error`: the period and phase its amplitudes were fitted at (the
    /// residual's strongest line), with their deviations.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub line: Option<crate::periodic::PeriodicLine>,
}

/// An exact alias of a found effect.
#[derive(Debug, Clone, Serialize)]
pub struct Equivalent {
    pub name: String,
    pub value: f64,
    pub std: f64,
    pub unit: String,
    pub note: String,
}

/// `dvl.sound_speed` as the cause of a DVL scale change: the DVL's velocity scales with the
/// assumed over the true sound speed, so a scale `value` (nominal `nominal_scale`, with the
/// nominal true sound speed `nominal_sound_speed`) is the same as a true sound speed of
/// `nominal_sound_speed × nominal_scale / value`.
pub(crate) fn sound_speed_equivalent(
    value: f64,
    std: f64,
    nominal_scale: f64,
    nominal_sound_speed: f64,
) -> Option<Equivalent> {
    if !(value.is_finite() && value > 0.0 && nominal_scale > 0.0) {
        return None;
    }
    let c = nominal_sound_speed * nominal_scale / value;
    Some(Equivalent {
        name: "dvl.sound_speed".into(),
        value: c,
        std: c * std / value,
        unit: "m/s".into(),
        note: format!(
            "the same change as a true sound speed of {c:.1} m/s at the DVL where it assumed \
             {nominal_sound_speed:.0} m/s (a Janus DVL's velocity scales with assumed / true): \
             measure the sound speed (CTD) to tell the two apart; if it is the sound speed, set \
             [navigation] dvl_sound_speed_source = \"value\" and sound_speed_m_s = {c:.1}"
        ),
    })
}

/// Two effects the motion cannot tell apart.
#[derive(Debug, Clone, Serialize)]
pub struct Unseparable {
    /// Two effects, or an effect and the group of effects that together mimic it.
    pub effects: Vec<String>,
    /// Largest canonical correlation of their sensitivities on this motion (for a group: of the
    /// first effect's component with the group's).
    pub correlation: f64,
    pub note: String,
}

/// Components of an effect the motion does not excite.
#[derive(Debug, Clone, Serialize)]
pub struct Unobservable {
    pub name: String,
    pub components: Vec<usize>,
}

/// An estimate beyond what the sensor's class allows.
#[derive(Debug, Clone, Serialize)]
pub struct Implausible {
    pub name: String,
    pub channel: ChannelKind,
    /// The estimate the selection reached (the effect's unit).
    pub value: serde_json::Value,
    pub unit: String,
    /// The largest departure from nominal the class allows, per component.
    pub limit: f64,
    pub note: String,
}

/// A candidate the data point at without determining it: it lowers the held-out score, but its
/// estimate does not stand out from nominal by the significance test once the residual's
/// correlation in time is allowed for (a slowly varying error it cannot be told from on this
/// motion). Not named, not written into the model.
#[derive(Debug, Clone, Serialize)]
pub struct Undetermined {
    pub name: String,
    pub channel: ChannelKind,
    /// The estimate, fitted with the effects selected before it (the effect's unit).
    pub value: serde_json::Value,
    pub std: serde_json::Value,
    pub nominal: serde_json::Value,
    pub unit: String,
    /// Its largest departure from nominal, in standard deviations.
    pub sigmas: f64,
    /// How much wider its deviations are than white residuals would give.
    pub widening: f64,
    /// The held-out score without it and with it.
    pub held_out_before: f64,
    pub held_out_after: f64,
    pub note: String,
}

/// Structure left in a residual after the selected effects.
#[derive(Debug, Clone, Serialize)]
pub struct Unexplained {
    pub channel: ChannelKind,
    pub component: usize,
    pub note: String,
}

/// One channel before and after discovery.
#[derive(Debug, Clone, Serialize)]
pub struct ChannelReport {
    pub channel: ChannelKind,
    pub unit: String,
    pub epochs: usize,
    pub skipped: usize,
    /// Epochs the reference covers.
    pub compared: usize,
    pub held_out_mse_nominal: f64,
    pub held_out_mse_selected: f64,
    /// Per component: the residual of the nominal model.
    pub nominal: Vec<Description>,
    /// Per component: the residual with the selected effects.
    pub selected: Vec<Description>,
    /// The IMU channels: the Allan deviation of the residual with the selected effects, per
    /// cluster time (empty for the other channels).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub allan: Vec<AllanPoint>,
    /// The DVL channel: the strongest line of its residual with every other candidate fitted,
    /// standing out or not (`dvl.periodic_velocity_error` is a candidate only where it does).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub line: Option<crate::periodic::PeriodicLine>,
}

/// One cluster time of an Allan deviation: per component, in the channel's unit.
#[derive(Debug, Clone, Serialize)]
pub struct AllanPoint {
    pub tau_s: f64,
    pub deviation: Vec<f64>,
}

/// The held-out gain of one channel: fit on the first part, residual RMS on the rest.
#[derive(Debug, Clone, Serialize)]
pub struct ChannelGain {
    pub channel: ChannelKind,
    pub fit_fraction: f64,
    pub rms_before: Vec<f64>,
    pub rms_after: Vec<f64>,
}

/// The noise a channel shows once the effects found are modelled, as the simulator's noise
/// effect (`dvl.noise` per beam, `depth.noise`, `mag.noise` per axis).
#[derive(Debug, Clone, Serialize)]
pub struct NoiseEstimate {
    pub name: String,
    pub value: f64,
    pub unit: String,
    pub channel: ChannelKind,
    pub note: String,
}

/// One channel's residual series (for the report's plots), interleaved per component.
#[derive(Debug, Clone)]
pub struct ResidualSeries {
    pub channel: ChannelKind,
    pub times: Vec<f64>,
    pub nominal: Vec<f64>,
    pub selected: Vec<f64>,
}

/// The report (`--json` and `report.json`; `format_version` in docs/json.md).
#[derive(Debug, Clone, Serialize)]
pub struct DiscoverReport {
    pub inputs: Vec<String>,
    pub reference: String,
    pub channels: Vec<ChannelReport>,
    pub effects: Vec<FoundEffect>,
    pub unseparable: Vec<Unseparable>,
    pub unobservable: Vec<Unobservable>,
    pub unexplained: Vec<Unexplained>,
    pub gain: Vec<ChannelGain>,
    /// Noise per channel with the effects found (what `effects.toml` gives the simulator).
    pub noise: Vec<NoiseEstimate>,
    /// Navigation error before/after, per log with an IMU and a reference (the navigator's
    /// configuration from the nominal effects, then from the effects found on the first
    /// `fit_fraction` of each channel).
    pub navigation: Vec<NavigationGain>,
    /// What could not be analysed, and why.
    pub notes: Vec<String>,
    /// Effects the selection would have named with an estimate beyond what the sensor's class
    /// allows ([`crate::PLAUSIBLE`]): not named (they point at the reference or at an effect
    /// outside the vocabulary), the other effects fitted without them.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub implausible: Vec<Implausible>,
    /// Candidates the held-out score asks for and the significance test refuses, with their
    /// estimates ([`Undetermined`]).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub undetermined: Vec<Undetermined>,
    /// For every candidate not named: the smallest size the data would have named, so that an
    /// absent effect reads as "below the floor" or "not excited", never as silence.
    pub floors: Vec<DetectionFloor>,
    /// Several logs given as voyages: each one's own discovery, the installation effects the
    /// voyages share and whether they agree (absent for one log or `--one-voyage`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub voyages: Option<Box<Voyages>>,
    /// `--reference smoothed` on logs that also carry a reference: what separates that
    /// reference from the smoothed (IMU) motion.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub reference_against_imu: Vec<ReferenceAgainstImu>,
    /// The effects found that the navigator configuration (`--write-config`) leaves at their
    /// nominal values: with them the held-out navigation of some log got worse.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub withheld: Vec<Withheld>,
    /// Surface runs with effects withheld: the selection again without them, which is what the
    /// navigator configuration carries ([`crate::gnss_written::refit`]).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub refit: Option<Box<Refit>>,
    /// Each log's navigation with what the navigator configuration carries (the effects found
    /// less those withheld), when effects were withheld and some are left.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub navigation_written: Vec<NavigationGain>,
    /// Surface runs (compass, DVL and GNSS, no IMU): what their GNSS positions decide of the DVL
    /// installation ([`crate::gnss`]).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub gnss: Option<Box<crate::gnss_evidence::GnssEvidence>>,
    /// Each magnetic compass's declination not applied (surface runs whose header says so).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub compass: Vec<auvnav_calibrate::surface::compass::CompassDeclination>,
    pub wall_s: f64,
    /// The nominal effects.
    #[serde(skip)]
    pub nominal_model: Effects,
    /// The nominal effects with the effects found (fitted on all readings).
    #[serde(skip)]
    pub model: Effects,
    /// The same, fitted on the first `fit_fraction` of each channel only.
    #[serde(skip)]
    pub held_out_model: Effects,
    #[serde(skip)]
    pub residuals: Vec<ResidualSeries>,
}

impl DiscoverReport {
    /// A report with nothing in it yet, on the nominal model `nominal`.
    pub fn new(nominal: &Effects) -> DiscoverReport {
        DiscoverReport {
            inputs: Vec::new(),
            reference: String::new(),
            channels: Vec::new(),
            effects: Vec::new(),
            unseparable: Vec::new(),
            unobservable: Vec::new(),
            unexplained: Vec::new(),
            gain: Vec::new(),
            noise: Vec::new(),
            navigation: Vec::new(),
            notes: Vec::new(),
            implausible: Vec::new(),
            undetermined: Vec::new(),
            floors: Vec::new(),
            voyages: None,
            reference_against_imu: Vec::new(),
            withheld: Vec::new(),
            refit: None,
            gnss: None,
            compass: Vec::new(),
            navigation_written: Vec::new(),
            wall_s: 0.0,
            nominal_model: nominal.clone(),
            model: nominal.clone(),
            held_out_model: nominal.clone(),
            residuals: Vec::new(),
        }
    }
}

/// How large a candidate must be for this motion and noise to name it.
#[derive(Debug, Clone, Serialize)]
pub struct DetectionFloor {
    pub name: String,
    pub channel: ChannelKind,
    /// Per component: the smallest departure from the nominal value the selection would name
    /// (the larger of `min_sigma` standard deviations of the candidate fitted with the effects
    /// found, allowing for correlated residuals, and the size that lowers the held-out score by
    /// `min_gain`), in the effect's unit; `None` where the motion does not excite the component.
    pub floor: Vec<Option<f64>>,
    pub unit: String,
    /// The significance test's standard deviations (`min_sigma`).
    pub sigmas: f64,
}

impl DetectionFloor {
    /// The floor in words, e.g. `dvl.time_offset (dvl): would need about ±1.04 s to be named on
    /// this motion (…); smaller is neither found nor excluded`.
    pub fn describe(&self) -> String {
        let min_sigma = self.sigmas;
        let parts: Vec<String> = self
            .floor
            .iter()
            .map(|f| match f {
                Some(v) => format!("±{}", sig(*v)),
                None => "not excited".into(),
            })
            .collect();
        let text = if parts.len() == 1 {
            parts[0].clone()
        } else {
            format!("[{}]", parts.join(", "))
        };
        if self.floor.iter().all(Option::is_none) {
            format!(
                "{} ({}): not excited by this motion",
                self.name,
                self.channel.name()
            )
        } else {
            format!(
                "{} ({}): would need about {text} {} to be named on this motion ({min_sigma}σ \
                 and the held-out gain, linearised); smaller is neither found nor excluded",
                self.name,
                self.channel.name(),
                self.unit
            )
        }
    }
}

/// Three significant digits.
pub(crate) fn sig(v: f64) -> String {
    if v == 0.0 || !v.is_finite() {
        return format!("{v}");
    }
    let digits = (2 - v.abs().log10().floor() as i32).max(0) as usize;
    format!("{v:.digits$}")
}

/// Navigation error of one log before/after.
#[derive(Debug, Clone, Serialize)]
pub struct NavigationGain {
    pub log: String,
    /// Where the rest of the configuration came from (the log header or the defaults).
    pub configuration: String,
    pub before: Accuracy,
    pub after: Accuracy,
    pub dvl_fused_before: u64,
    pub dvl_rejected_before: u64,
    pub dvl_fused_after: u64,
    pub dvl_rejected_after: u64,
    /// The reference was moved to the IMU by this lever arm (body axes, m) before it scored
    /// either run: where `--reference smoothed` found the log's reference to sit on the vehicle.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub reference_lever_arm_m: Option<[f64; 3]>,
    /// The effects make the navigation of this log worse ([`NavigationGain::judge`]).
    pub worse: bool,
    /// What the comparison shows, in words.
    pub verdict: String,
}

/// What the navigator configuration carries once effects are withheld: discovery run again with
/// them never selected, so that the effects kept are fitted without them (fitted beside them, an
/// effect the motion couples to a withheld one carries part of it).
#[derive(Debug, Clone, Serialize)]
pub struct Refit {
    /// The effects never selected.
    pub without: Vec<String>,
    /// What the refit names (values fitted without `without`).
    pub effects: Vec<FoundEffect>,
    /// What the refit withholds in its turn (its own navigation check).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub withheld: Vec<Withheld>,
    /// One sentence per effect kept, named or not: its value beside the withheld effects and
    /// without them.
    pub changes: Vec<String>,
    /// The nominal effects with what the refit names.
    #[serde(skip)]
    pub model: Effects,
}

/// An effect found that the navigator configuration leaves out, and why.
#[derive(Debug, Clone, Serialize)]
pub struct Withheld {
    pub name: String,
    pub note: String,
}

impl NavigationGain {
    /// Whether the run `after` navigates worse than `before`, and the sentence that says so.
    /// Worse: its position error (RMS) against the reference grows, or its horizontal
    /// velocity error does (where the reference has velocities). The sentence also gives the
    /// RMS by which the reference's own position departs from the integral of its velocity
    /// ([`Accuracy::truth_position_against_velocity_rms_m`]) when a position error grows by less
    /// than that: such a reference does not say whether its position or its velocity is the
    /// one in error, so the growth still counts, but the engineer should know that the
    /// reference cannot tell that difference apart.
    pub fn judge(before: &Accuracy, after: &Accuracy) -> (bool, String) {
        let (pb, pa) = (before.horizontal_error_rms_m, after.horizontal_error_rms_m);
        let own = before.truth_position_against_velocity_rms_m;
        let (vb, va) = (
            before.horizontal_velocity_error_rms_m_s,
            after.horizontal_velocity_error_rms_m_s,
        );
        let with_velocity = vb > 0.0 && va > 0.0;
        let velocity_worse = with_velocity && va > vb;
        let position_worse = pa > pb;
        let mut text = format!("position RMS {pb:.2} -> {pa:.2} m");
        if position_worse && pa - pb <= own {
            text.push_str(&format!(
                " (less than the {own:.2} m RMS by which the reference's position departs from \
                 the integral of its own velocity)"
            ));
        }
        if with_velocity {
            text.push_str(&format!(
                ", velocity RMS {:.1} -> {:.1} mm/s",
                1e3 * vb,
                1e3 * va
            ));
        }
        let head = match (velocity_worse, position_worse) {
            (false, false) => "not worse",
            (true, true) => "worse in velocity and position",
            (true, false) => "worse in velocity",
            (false, true) => "worse in position",
        };
        (velocity_worse || position_worse, format!("{head}: {text}"))
    }
}

/// One voyage's estimate of an effect.
#[derive(Debug, Clone, Serialize)]
pub struct VoyageEstimate {
    pub log: String,
    pub value: serde_json::Value,
    /// One sigma (null where this voyage's motion does not determine the component).
    pub std: serde_json::Value,
}

/// An installation effect the voyages were tested on together.
#[derive(Debug, Clone, Serialize)]
pub struct SharedEffect {
    pub name: String,
    pub channel: ChannelKind,
    pub unit: String,
    /// The information-weighted mean of the voyages' estimates.
    pub value: serde_json::Value,
    pub std: serde_json::Value,
    pub nominal: serde_json::Value,
    /// Each voyage's estimate, fitted with the other effects of the shared set and its own.
    pub voyages: Vec<VoyageEstimate>,
    /// Σ over voyages of (estimate − mean)ᵀ C⁻¹ (estimate − mean).
    pub chi2: f64,
    pub dof: usize,
    /// The χ² at which the voyages are taken to disagree (1 %; Welch's limit where the voyages'
    /// deviations are estimated from correlated residuals, the χ² quantile where they are white).
    pub chi2_limit: f64,
    /// Relative drop of the leave-one-voyage-out mean squared residual when the effect was added.
    pub held_out_gain: f64,
    pub verdict: String,
    /// For voyages that disagree: the largest set of voyages (at least half) that agree, found
    /// by setting aside the most departing voyage in turn; for the engineer to look at the
    /// voyages left out, never a finding by itself.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub agreeing: Option<Agreeing>,
    /// The voyages set aside because they depart from what the others agree on (at most a
    /// quarter of them): each fits its own value, the others' agreement is without them, and
    /// the engineer should look at them. An effect can still end inconsistent after some were
    /// set aside.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub departing: Vec<String>,
}

/// Voyages that agree once the most departing ones are set aside.
#[derive(Debug, Clone, Serialize)]
pub struct Agreeing {
    pub left_out: Vec<String>,
    pub voyages: usize,
    pub value: serde_json::Value,
    pub std: serde_json::Value,
}

/// An effect named by voyages alone: per-voyage effects, or installation effects the voyages
/// together did not confirm.
#[derive(Debug, Clone, Serialize)]
pub struct NamedAlone {
    pub name: String,
    pub channel: ChannelKind,
    pub unit: String,
    pub voyages: Vec<VoyageEstimate>,
    /// An installation effect not confirmed although a few voyages depart from what the
    /// others agree on (at most a quarter): what the others agree on, shared by them. It was
    /// not named because, shared by them, it did not pass the test or lower the held-out
    /// residual enough; the voyages are not reported as disagreeing.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub agreeing: Option<Agreeing>,
}

/// One channel's leave-one-voyage-out score.
#[derive(Debug, Clone, Serialize)]
pub struct VoyageScore {
    pub channel: ChannelKind,
    pub voyages: usize,
    /// Mean squared residual over all voyages, each predicted with the nominal installation (its
    /// own per-voyage effects fitted).
    pub mse_nominal: f64,
    /// The same with the shared effects fitted on the other voyages.
    pub mse_shared: f64,
}

/// What several voyages say together (`voyages` in the report).
#[derive(Debug, Clone, Serialize)]
pub struct Voyages {
    /// Each voyage's own discovery.
    pub voyages: Vec<DiscoverReport>,
    /// Installation effects the voyages agree on, significant together.
    pub shared: Vec<SharedEffect>,
    /// Installation effects the voyages disagree on beyond their uncertainties.
    pub inconsistent: Vec<SharedEffect>,
    /// Effects of one voyage (biases, water, place), where each voyage named them.
    pub per_voyage: Vec<NamedAlone>,
    /// Installation effects some voyages named alone that the voyages together do not.
    pub not_confirmed: Vec<NamedAlone>,
    pub scores: Vec<VoyageScore>,
    /// Per voyage: the nominal model with the shared effects fitted on the other voyages (the
    /// held-out model its navigation is replayed with).
    #[serde(skip)]
    pub held_out_models: Vec<Effects>,
}

/// What separates a log's own reference from its smoothed motion.
#[derive(Debug, Clone, Serialize)]
pub struct ReferenceAgainstImu {
    pub log: String,
    /// Effects of the reference's velocity, read as a DVL on the vehicle against the smoothed
    /// motion (`dvl.lever_arm`: where on the vehicle the reference's velocity is taken;
    /// `dvl.time_offset`: its lag), with their deviations.
    pub effects: Vec<(String, serde_json::Value, serde_json::Value)>,
    /// The smoother's own estimate of the DVL installation (against the IMU).
    pub smoothed_installation: Option<serde_json::Value>,
}

/// The numbers of an effect value as the report writes it (a number or an array); None when a
/// component is not a number.
pub fn values_of(v: &serde_json::Value) -> Option<Vec<f64>> {
    components_of(v).into_iter().collect()
}

/// Per component, the number of an effect value as the report writes it (a number or an
/// array); None for a component that is not a number (a deviation the motion does not give).
pub fn components_of(v: &serde_json::Value) -> Vec<Option<f64>> {
    match v {
        serde_json::Value::Array(a) => a.iter().map(|x| x.as_f64()).collect(),
        x => vec![x.as_f64()],
    }
}

#[cfg(test)]
#[path = "findings_tests.rs"]
mod tests;
