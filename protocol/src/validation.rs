//! What values the protocol accepts: every message is checked here before it is encoded and
//! after it is decoded, so a NaN or an out-of-range value never reaches a core.

use thiserror::Error;

/// A value outside what the protocol accepts.
#[derive(Debug, Clone, PartialEq, Error)]
#[error("{message}.{field}: {reason}")]
pub struct ValidationError {
    pub message: &'static str,
    pub field: &'static str,
    pub reason: String,
}

/// Longest text in a status or allocation result, in bytes.
pub const MAX_TEXT: usize = 1024;
/// Most joints in one allocation result.
pub const MAX_JOINTS: usize = 16;
/// Most joints in one board message (kind 9).
pub const MAX_BOARD_JOINTS: usize = 1024;
/// Largest |torque| accepted [N·m]: far above any joint of the rig, catches garbage.
pub const MAX_TORQUE_NM: f64 = 1e4;

/// Checks the fields of one message, naming the message and the field in every error.
pub(crate) struct Check(pub(crate) &'static str);

impl Check {
    pub(crate) fn err(&self, field: &'static str, reason: impl Into<String>) -> ValidationError {
        ValidationError {
            message: self.0,
            field,
            reason: reason.into(),
        }
    }

    pub(crate) fn finite(&self, field: &'static str, v: f64) -> Result<(), ValidationError> {
        if v.is_finite() {
            Ok(())
        } else {
            Err(self.err(field, format!("must be a finite number, got {v}")))
        }
    }

    pub(crate) fn within(
        &self,
        field: &'static str,
        v: f64,
        lo: f64,
        hi: f64,
    ) -> Result<(), ValidationError> {
        self.finite(field, v)?;
        if v < lo || v > hi {
            return Err(self.err(field, format!("{v} is outside [{lo}, {hi}]")));
        }
        Ok(())
    }

    pub(crate) fn opt_within(
        &self,
        field: &'static str,
        v: Option<f64>,
        lo: f64,
        hi: f64,
    ) -> Result<(), ValidationError> {
        v.map_or(Ok(()), |v| self.within(field, v, lo, hi))
    }

    pub(crate) fn time(&self, field: &'static str, t_ns: u64) -> Result<(), ValidationError> {
        if t_ns == 0 {
            Err(self.err(field, "acquisition time is unset (0)"))
        } else {
            Ok(())
        }
    }

    pub(crate) fn text(&self, field: &'static str, s: &str) -> Result<(), ValidationError> {
        if s.len() > MAX_TEXT {
            return Err(self.err(field, format!("{} bytes, at most {MAX_TEXT}", s.len())));
        }
        Ok(())
    }
}
