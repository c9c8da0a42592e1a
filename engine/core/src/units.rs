//! Number types the scenario format and the scene's components share: values checked
//! when they are read.

use serde::de::{self, Deserializer};
use serde::{Deserialize, Serialize};

/// A number as an error message shows it: as written between 1e-4 and 1e6 in
/// magnitude (and 0), in exponent form beyond, so 1e-320 does not print as 320 digits.
pub fn shown(x: f64) -> String {
    let m = x.abs();
    if x == 0.0 || !x.is_finite() || (1e-4..1e6).contains(&m) {
        format!("{x}")
    } else {
        format!("{x:e}")
    }
}

/// A number that must be > 0.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
#[serde(transparent)]
pub struct Positive(pub f64);

impl<'de> Deserialize<'de> for Positive {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let v = f64::deserialize(d)?;
        if v > 0.0 && v.is_finite() {
            Ok(Positive(v))
        } else {
            Err(de::Error::custom(format!(
                "{v} is out of range; accepted: a finite number > 0"
            )))
        }
    }
}
