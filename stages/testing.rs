//! Helpers shared by the stages' unit tests.

use std::fmt::Display;

/// Asserts that `validate` accepts the default parameters, and that it rejects the defaults
/// changed by each `change` of `rejected` with exactly the `message` given.
pub(crate) fn assert_validation<P: Default, E: Display>(
    validate: impl Fn(&P) -> Result<(), E>,
    rejected: &[(fn(&mut P), &str)],
) {
    if let Err(e) = validate(&P::default()) {
        panic!("the default parameters are rejected: {e}");
    }
    for (change, message) in rejected {
        let mut p = P::default();
        change(&mut p);
        match validate(&p) {
            Ok(()) => panic!("accepted, but expected {message:?}"),
            Err(e) => assert_eq!(e.to_string(), *message),
        }
    }
}
