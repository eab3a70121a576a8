//! Validation helpers shared by the environments' option structs.
use super::EnvError;

pub(crate) struct Check<'a> {
    pub env: &'a str,
}

impl Check<'_> {
    fn fail(&self, message: String) -> EnvError {
        EnvError::InvalidOption { env: self.env.to_string(), message }
    }
    pub fn non_negative(&self, name: &str, v: f64) -> Result<(), EnvError> {
        if v.is_finite() && v >= 0.0 {
            Ok(())
        } else {
            Err(self.fail(format!("{name} must be a finite number >= 0, got {v}")))
        }
    }
    pub fn range(&self, name: &str, r: [f64; 2]) -> Result<(), EnvError> {
        if r[0].is_nan() || r[1].is_nan() || r[0] >= r[1] {
            Err(self.fail(format!("{name} must be [low, high] with low < high, got {r:?}")))
        } else {
            Ok(())
        }
    }
    pub fn positive_count(&self, name: &str, v: usize) -> Result<(), EnvError> {
        if v > 0 {
            Ok(())
        } else {
            Err(self.fail(format!("{name} must be at least 1")))
        }
    }
    pub fn within(&self, name: &str, v: f64, low: f64, high: f64) -> Result<(), EnvError> {
        if v.is_finite() && v >= low && v <= high {
            Ok(())
        } else {
            Err(self.fail(format!("{name} must lie in [{low}, {high}], got {v}")))
        }
    }
}
