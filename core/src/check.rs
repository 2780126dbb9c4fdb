//! Typed parameter errors: what a `validate()` of a parameter struct returns. The message
//! names the key, the allowed values and the value given, e.g.
//! `synthesize.width must be in 1..=16384, got 0`.

use std::fmt::Display;

/// A parameter that is out of its range or otherwise unusable.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ParamError {
    #[error("{key} must be in {min}..={max}, got {value}")]
    OutOfRange {
        key: String,
        min: String,
        max: String,
        value: String,
    },
    /// `message` completes the sentence that starts with the key, e.g. "must be a positive
    /// number, got -1".
    #[error("{key} {message}")]
    Invalid { key: String, message: String },
}

impl ParamError {
    pub fn invalid(key: impl Into<String>, message: impl Into<String>) -> Self {
        ParamError::Invalid {
            key: key.into(),
            message: message.into(),
        }
    }

    /// The key the error names.
    pub fn key(&self) -> &str {
        match self {
            ParamError::OutOfRange { key, .. } | ParamError::Invalid { key, .. } => key,
        }
    }
}

/// Range check used by validators: the error names the key, the range and the value.
pub fn check_range<T: PartialOrd + Display>(
    key: &str,
    v: T,
    lo: T,
    hi: T,
) -> Result<(), ParamError> {
    if v >= lo && v <= hi {
        Ok(())
    } else {
        Err(ParamError::OutOfRange {
            key: key.to_owned(),
            min: lo.to_string(),
            max: hi.to_string(),
            value: v.to_string(),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn messages_name_the_key_the_range_and_the_value() {
        assert_eq!(
            check_range("a.b", 3, 1, 2).unwrap_err().to_string(),
            "a.b must be in 1..=2, got 3"
        );
        assert_eq!(
            check_range("a.c", -0.5f32, 0.0, 4.0)
                .unwrap_err()
                .to_string(),
            "a.c must be in 0..=4, got -0.5"
        );
        assert!(check_range("a.b", 2, 1, 2).is_ok());
        assert!(check_range("a.b", f32::NAN, 0.0, 1.0).is_err());
        let e = ParamError::invalid("extract.sigma", "must be a positive number, got -1");
        assert_eq!(
            e.to_string(),
            "extract.sigma must be a positive number, got -1"
        );
        assert_eq!(e.key(), "extract.sigma");
    }
}
