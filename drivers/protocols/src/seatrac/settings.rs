//! SeaTrac driver settings (`[settings.seatrac]`): the beacons a SeaTrac ranges as LBL
//! transponders.

use serde::{Deserialize, Serialize};

/// SeaTrac settings (`[settings.seatrac]`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SeatracSettings {
    /// Beacon IDs (1..15, at most 4, distinct) whose fixes are published as ranges on
    /// `acoustic_ranges`, beacon `range_beacons[k]` as receiver k of the range aid; the fixes of
    /// other beacons stay USBL fixes on `usbl`. Default none.
    pub range_beacons: BeaconList,
}

/// Up to four beacon IDs, in order (a TOML array).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(try_from = "Vec<u8>", into = "Vec<u8>")]
pub struct BeaconList {
    ids: [u8; 4],
    len: u8,
}

impl BeaconList {
    pub fn ids(&self) -> &[u8] {
        &self.ids[..usize::from(self.len)]
    }

    /// Beacon `id`'s slot.
    pub fn slot(&self, id: u8) -> Option<usize> {
        self.ids().iter().position(|&b| b == id)
    }

    /// Why the list cannot be used: IDs outside 1..15 or repeated.
    pub fn problem(&self) -> Option<String> {
        let ids = self.ids();
        if let Some(b) = ids.iter().find(|&&b| !(1..=15).contains(&b)) {
            return Some(format!("beacon ID {b} outside 1..=15"));
        }
        for (i, b) in ids.iter().enumerate() {
            if ids[..i].contains(b) {
                return Some(format!("beacon ID {b} given twice"));
            }
        }
        None
    }
}

impl TryFrom<Vec<u8>> for BeaconList {
    type Error = String;
    fn try_from(v: Vec<u8>) -> Result<Self, String> {
        if v.len() > 4 {
            return Err(format!(
                "range_beacons: {} beacons; at most 4 (the range aid's receivers)",
                v.len()
            ));
        }
        let mut ids = [0; 4];
        ids[..v.len()].copy_from_slice(&v);
        Ok(BeaconList {
            ids,
            len: v.len() as u8,
        })
    }
}

impl From<BeaconList> for Vec<u8> {
    fn from(b: BeaconList) -> Self {
        b.ids().to_vec()
    }
}
