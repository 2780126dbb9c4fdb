//! One trait for every artifact format, and a macro for the common shape of one: a metadata
//! value plus named arrays, with an owned form that writers fill and a borrowed form that
//! readers view in place.
//!
//! A format names its [`Kind`] (stored in the header, so a reader refuses a file of another
//! kind), how to write itself, and how to view an artifact of its kind. No method or stage
//! builds artifact bytes: methods return owned values from their nodes and receive views,
//! and the pipeline writes and opens the artifacts.

use super::{AlignedBytes, Artifact, ArtifactError, Kind};

/// An artifact format. `Self` is the owned value a node computes; [`Format::View`] is what a
/// node reading it sees (zero-copy where the arrays are used in place).
pub trait Format: Send + Sync + 'static {
    /// Stored in the header and checked before [`Format::decode`] runs.
    const KIND: Kind;
    /// The reader's form. For formats that algorithms mutate or index with cached adjacency
    /// (meshes), an owned copy; otherwise borrowed slices of the artifact.
    type View<'a>;
    /// The complete artifact bytes (header, metadata, arrays).
    fn write(&self) -> AlignedBytes;
    /// Views an artifact already checked to be of [`Format::KIND`]. Checks that lengths agree
    /// with each other and with the metadata, so damage is an error here and never an
    /// out-of-bounds index later.
    fn decode(a: &Artifact) -> Result<Self::View<'_>, ArtifactError>;

    /// Checks the kind, then decodes.
    fn view(a: &Artifact) -> Result<Self::View<'_>, ArtifactError> {
        a.expect_kind(Self::KIND)?;
        Self::decode(a)
    }
}

/// A format that can be read back as an owned value (what keyed pieces are: a piece outlives
/// the artifact it was read from).
pub trait ReadOwned: Format + Sized {
    fn read(a: &Artifact) -> Result<Self, ArtifactError>;
}

/// The error for arrays that disagree with each other or with the metadata.
pub fn inconsistent(what: impl Into<String>) -> ArtifactError {
    ArtifactError::Meta(what.into())
}

/// Implements [`Format`] for an owned/borrowed pair of structs that share field names: a
/// metadata field (any serde value) and array fields (`Vec<T>` in the owned struct, `&[T]` in
/// the borrowed one), written in the listed order. An optional `check` closure receives the
/// view and returns whether its arrays are consistent. The two structs may live in the
/// stages (the algorithms use them too); the artifact layer only gives them their format.
///
/// ```ignore
/// format_pair! {
///     Parameterization => ParamParts, kind: JumpParameterization, meta: meta,
///     arrays: [order, seeds, boxes],
///     check: |p| p.order.len() <= p.meta.vertices as usize,
/// }
/// ```
#[macro_export]
macro_rules! format_pair {
    (
        $owned:ty => $view:ident, kind: $kind:ident, meta: $meta:ident,
        arrays: [$($array:ident),* $(,)?]
        $(, check: |$v:ident| $check:expr)? $(,)?
    ) => {
        impl $crate::artifact::Format for $owned {
            const KIND: $crate::artifact::Kind = $crate::artifact::Kind::$kind;
            type View<'a> = $view<'a>;
            fn write(&self) -> $crate::artifact::AlignedBytes {
                $crate::artifact::ArtifactWriter::new(Self::KIND, &self.$meta)
                    $(.array(stringify!($array), &self.$array))*
                    .finish()
            }
            fn decode(
                a: &$crate::artifact::Artifact,
            ) -> Result<$view<'_>, $crate::artifact::ArtifactError> {
                let view = $view {
                    $meta: a.meta()?,
                    $($array: a.array(stringify!($array))?,)*
                };
                $(
                    let $v = &view;
                    if !$check {
                        return Err($crate::artifact::format::inconsistent(concat!(
                            stringify!($owned),
                            " arrays are inconsistent"
                        )));
                    }
                )?
                Ok(view)
            }
        }
    };
}
