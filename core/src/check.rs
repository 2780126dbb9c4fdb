//! Typed parameter errors: what a `validate()` of a parameter struct returns. The message
//! names the key, the allowed values and the value given, e.g.
//! `synthesize.width must be in 1..=16384, got 0`.

use crate::math::PureMath;
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

    /// An out-of-range error with the range written as given (`"0"`, `"1e9"`), for checks
    /// whose bounds do not print as wanted through [`check_range`].
    pub fn out_of_range(
        key: impl Into<String>,
        min: impl Display,
        max: impl Display,
        value: impl Display,
    ) -> Self {
        ParamError::OutOfRange {
            key: key.into(),
            min: min.to_string(),
            max: max.to_string(),
            value: value.to_string(),
        }
    }

    /// The key the error names.
    pub fn key(&self) -> &str {
        match self {
            ParamError::OutOfRange { key, .. } | ParamError::Invalid { key, .. } => key,
        }
    }

    /// The same error with its key prefixed by `context` and `": "`: a struct's validator
    /// checks `levels`, its caller reports `jump map: levels`.
    pub fn within(mut self, context: &str) -> Self {
        match &mut self {
            ParamError::OutOfRange { key, .. } | ParamError::Invalid { key, .. } => {
                *key = format!("{context}: {key}")
            }
        }
        self
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
        let e = check_range("levels", 9, 1, 8)
            .unwrap_err()
            .within("jump map");
        assert_eq!(e.to_string(), "jump map: levels must be in 1..=8, got 9");
        assert_eq!(
            ParamError::out_of_range("c", "0", "1e9", -1.0).to_string(),
            "c must be in 0..=1e9, got -1"
        );
    }
}

/// A number printed with four significant digits, in scientific notation when it is very
/// small or very large, so that a message never says "0.0000" of a value that is not zero.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Significant(pub f64);

impl Display for Significant {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let x = self.0;
        if x == 0.0 || !x.is_finite() {
            write!(f, "{x}")
        } else if !(1e-3..1e6).contains(&x.abs()) {
            write!(f, "{x:.3e}")
        } else {
            let digits = (3 - x.abs().log10_pure().floor() as i32).max(0) as usize;
            write!(f, "{x:.digits$}")
        }
    }
}

#[cfg(test)]
mod significant_tests {
    use super::Significant;

    #[test]
    fn four_significant_digits_and_never_a_false_zero() {
        assert_eq!(Significant(0.0).to_string(), "0");
        assert_eq!(Significant(123.456).to_string(), "123.5");
        assert_eq!(Significant(0.0123456).to_string(), "0.01235");
        assert_eq!(Significant(1.6e-35).to_string(), "1.600e-35");
        assert_eq!(Significant(2.5e9).to_string(), "2.500e9");
    }
}
