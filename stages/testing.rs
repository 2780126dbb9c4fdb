//! Helpers shared by the stages' unit tests.

/// Asserts that the default `P` validates and that each change of one field of the defaults
/// is rejected with exactly the message given:
///
/// ```ignore
/// assert_validation!(P {
///     field: bad_value => "context: field must be …, got …",
/// });
/// ```
macro_rules! assert_validation {
    ($params:ident { $($field:ident: $value:expr => $message:expr),+ $(,)? }) => {{
        if let Err(e) = $params::default().validate() {
            panic!("the default parameters are rejected: {e}");
        }
        $(
            let bad = $params {
                $field: $value,
                ..$params::default()
            };
            match bad.validate() {
                Ok(()) => panic!("{} = {:?} is accepted", stringify!($field), bad.$field),
                Err(e) => assert_eq!(e.to_string(), $message),
            }
        )+
    }};
}
pub(crate) use assert_validation;
