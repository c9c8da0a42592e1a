//! Number types the scenario format and the scene's components share: values checked
//! when they are read.

use serde::de::{self, Deserializer};
use serde::{Deserialize, Serialize};

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
