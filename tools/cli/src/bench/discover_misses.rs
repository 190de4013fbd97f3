//! How `auvnav bench discover` counts the hidden effects a report does not name, by what the
//! report says of each at the hidden size.

use crate::discover::hidden_effects::Miss;
use serde::Serialize;

/// Hidden effects not named, by what the report says of them at the hidden size.
#[derive(Debug, Default, Serialize)]
pub(super) struct Misses {
    not_excited: usize,
    below_the_floor: usize,
    /// Several voyages disagree on it (reported as inconsistent).
    inconsistent: usize,
    /// Above the floor, listed as pointed at but not determined.
    undetermined: usize,
    /// The report's floor says the hidden size would have been named: unaccounted for.
    silent: usize,
}

impl Misses {
    pub(super) fn of<'a>(misses: impl Iterator<Item = &'a Miss>) -> Misses {
        let mut m = Misses::default();
        for x in misses {
            match x {
                Miss::NotExcited => m.not_excited += 1,
                Miss::BelowTheFloor => m.below_the_floor += 1,
                Miss::Inconsistent => m.inconsistent += 1,
                Miss::Undetermined => m.undetermined += 1,
                Miss::Silent => m.silent += 1,
            }
        }
        m
    }

    /// Of `trials` hidden trials, those the report neither puts below its floor nor calls not
    /// excited.
    pub(super) fn detectable(&self, trials: usize) -> usize {
        trials.saturating_sub(self.below_the_floor + self.not_excited)
    }

    pub(super) fn describe(&self) -> String {
        format!(
            "not named: {} reported not excited, {} below the floor, {} inconsistent across \
             voyages, {} pointed at but not determined, {} silent",
            self.not_excited,
            self.below_the_floor,
            self.inconsistent,
            self.undetermined,
            self.silent
        )
    }
}
