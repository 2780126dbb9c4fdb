//! Typed wiring: how a method declares a node.
//!
//! A method calls [`Dag::node`] with a [`NodeSpec`] (stage, algorithm, code version), a
//! parameter value, its inputs and a compute function, and gets back a [`Handle`] typed by
//! the node's output [`Format`]. Inputs are any shape built from handles: one handle, a
//! tuple, a `Vec`, an `Option`, a [`FileHandle`] for an input file's bytes, and [`Keyed`] to
//! say that an input is part of the key of the node's pieces. The compute function receives
//! views of its inputs in that same shape, so the wiring and the computation cannot disagree
//! about which input is which, and no index into an input list appears in a method.
//!
//! Keys are exactly what they were before the typed API: blake3 over the stage, the
//! algorithm, the code version, the parameters' canonical bytes and the inputs' content
//! hashes in declared order (with their kind, node or file). The parameters' canonical bytes
//! and their JSON for people come from the same serde value, so they cannot drift apart.

use super::{Dag, FileInput, InputRef, Node, NodeContext, NodeError, Stage};
use crate::artifact::{Format, canonical_bytes};
use std::marker::PhantomData;
use std::path::Path;

/// The artifact of a node, typed by its format. Only [`Dag::node`] makes one.
///
/// A node that wants an image takes a `Handle<Image>`, and its compute function sees an
/// `ImageView`:
///
/// ```
/// use texsyn::image::Image;
/// use texsyn::pipeline::{Dag, Handle, NodeSpec, Stage};
///
/// fn brighten(dag: &mut Dag, image: Handle<Image>) -> Handle<Image> {
///     dag.node(NodeSpec::new(Stage::Synthesize, "brighten", 1), 2.0f32, image, |_, gain, v| {
///         let mut out = Image::new(v.width, v.height);
///         for (o, p) in out.pixels.iter_mut().zip(v.pixels) {
///             *o = p.map(|c| c * gain);
///         }
///         Ok(out)
///     })
/// }
///
/// fn wire(dag: &mut Dag, image: Handle<Image>) -> Handle<Image> {
///     brighten(dag, image)
/// }
/// ```
///
/// and passing it a mesh's handle does not compile (the same code as above but for the
/// handle's type; with `Handle<Image>` there, this example compiles and its test fails):
///
/// ```compile_fail,E0308
/// use texsyn::geom::Mesh;
/// use texsyn::image::Image;
/// use texsyn::pipeline::{Dag, Handle, NodeSpec, Stage};
///
/// fn brighten(dag: &mut Dag, image: Handle<Image>) -> Handle<Image> {
///     dag.node(NodeSpec::new(Stage::Synthesize, "brighten", 1), 2.0f32, image, |_, gain, v| {
///         let mut out = Image::new(v.width, v.height);
///         for (o, p) in out.pixels.iter_mut().zip(v.pixels) {
///             *o = p.map(|c| c * gain);
///         }
///         Ok(out)
///     })
/// }
///
/// fn wire(dag: &mut Dag, mesh: Handle<Mesh>) -> Handle<Image> {
///     brighten(dag, mesh)
/// }
/// ```
pub struct Handle<F> {
    index: usize,
    _format: PhantomData<fn() -> F>,
}

impl<F> Clone for Handle<F> {
    fn clone(&self) -> Self {
        *self
    }
}
impl<F> Copy for Handle<F> {}

impl<F> std::fmt::Debug for Handle<F> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "Handle({} of {})",
            self.index,
            std::any::type_name::<F>()
        )
    }
}

impl<F> Handle<F> {
    /// The node's position in the DAG (for reports and the run result's artifacts).
    pub fn index(self) -> usize {
        self.index
    }
}

/// An input file's bytes, for nodes that need the file itself (an exporter that copies the
/// exemplar's original PNG, an importer that parses it).
#[derive(Clone, Copy, Debug)]
pub struct FileHandle {
    index: usize,
}

/// Marks an input as part of the key of the node's pieces (see [`NodeSpec::pieces`]). Its
/// view is the wrapped input's view.
#[derive(Clone, Copy, Debug)]
pub struct Keyed<I>(pub I);

/// One input as the DAG records it.
#[doc(hidden)]
pub struct Declared {
    pub(crate) input: InputRef,
    /// Its content hash goes into the key of the node's pieces.
    pub(crate) keyed: bool,
}

/// Anything a node can take as inputs. Implemented for handles and for tuples, vectors and
/// options of inputs; the view has the same shape.
pub trait Inputs: Send + Sync + 'static {
    type View<'a>;
    #[doc(hidden)]
    fn declare(&self, keyed: bool, out: &mut Vec<Declared>);
    #[doc(hidden)]
    fn view<'a>(&self, ctx: &mut InputCursor<'a, '_>) -> Result<Self::View<'a>, NodeError>;
}

/// Walks a node's resolved inputs in declared order while [`Inputs::view`] rebuilds the
/// shape.
#[doc(hidden)]
pub struct InputCursor<'a, 'c> {
    pub(crate) data: std::slice::Iter<'c, super::InputData<'a>>,
}

impl<'a> InputCursor<'a, '_> {
    fn next(&mut self) -> super::InputData<'a> {
        *self
            .data
            .next()
            .expect("a node's inputs are viewed in the shape they were declared in")
    }
}

impl<F: Format> Inputs for Handle<F> {
    type View<'a> = F::View<'a>;
    fn declare(&self, keyed: bool, out: &mut Vec<Declared>) {
        out.push(Declared {
            input: InputRef::Node(self.index),
            keyed,
        });
    }
    fn view<'a>(&self, ctx: &mut InputCursor<'a, '_>) -> Result<F::View<'a>, NodeError> {
        match ctx.next() {
            super::InputData::Artifact(a) => Ok(F::view(a)?),
            super::InputData::File(_) => unreachable!("a handle declares a node input"),
        }
    }
}

impl Inputs for FileHandle {
    type View<'a> = &'a FileInput;
    fn declare(&self, keyed: bool, out: &mut Vec<Declared>) {
        out.push(Declared {
            input: InputRef::File(self.index),
            keyed,
        });
    }
    fn view<'a>(&self, ctx: &mut InputCursor<'a, '_>) -> Result<&'a FileInput, NodeError> {
        match ctx.next() {
            super::InputData::File(f) => Ok(f),
            super::InputData::Artifact(_) => unreachable!("a file handle declares a file input"),
        }
    }
}

impl<I: Inputs> Inputs for Keyed<I> {
    type View<'a> = I::View<'a>;
    fn declare(&self, _keyed: bool, out: &mut Vec<Declared>) {
        self.0.declare(true, out);
    }
    fn view<'a>(&self, ctx: &mut InputCursor<'a, '_>) -> Result<I::View<'a>, NodeError> {
        self.0.view(ctx)
    }
}

impl<I: Inputs> Inputs for Vec<I> {
    type View<'a> = Vec<I::View<'a>>;
    fn declare(&self, keyed: bool, out: &mut Vec<Declared>) {
        for i in self {
            i.declare(keyed, out);
        }
    }
    fn view<'a>(&self, ctx: &mut InputCursor<'a, '_>) -> Result<Self::View<'a>, NodeError> {
        self.iter().map(|i| i.view(ctx)).collect()
    }
}

impl<I: Inputs> Inputs for Option<I> {
    type View<'a> = Option<I::View<'a>>;
    fn declare(&self, keyed: bool, out: &mut Vec<Declared>) {
        if let Some(i) = self {
            i.declare(keyed, out);
        }
    }
    fn view<'a>(&self, ctx: &mut InputCursor<'a, '_>) -> Result<Self::View<'a>, NodeError> {
        self.as_ref().map(|i| i.view(ctx)).transpose()
    }
}

// Type parameters named A, B, C, …, skipping F and I, which name a format and an input
// elsewhere in this file.
impl<I: Inputs, const N: usize> Inputs for [I; N] {
    type View<'a> = [I::View<'a>; N];
    fn declare(&self, keyed: bool, out: &mut Vec<Declared>) {
        for i in self {
            i.declare(keyed, out);
        }
    }
    fn view<'a>(&self, ctx: &mut InputCursor<'a, '_>) -> Result<Self::View<'a>, NodeError> {
        let views: Vec<I::View<'a>> = self.iter().map(|i| i.view(ctx)).collect::<Result<_, _>>()?;
        Ok(views
            .try_into()
            .unwrap_or_else(|_| unreachable!("one view per element")))
    }
}

macro_rules! tuple_inputs {
    ($($name:ident),+) => {
        impl<$($name: Inputs),+> Inputs for ($($name,)+) {
            type View<'a> = ($($name::View<'a>,)+);
            #[allow(non_snake_case)]
            fn declare(&self, keyed: bool, out: &mut Vec<Declared>) {
                let ($($name,)+) = self;
                $($name.declare(keyed, out);)+
            }
            #[allow(non_snake_case)]
            fn view<'a>(&self, ctx: &mut InputCursor<'a, '_>) -> Result<Self::View<'a>, NodeError> {
                let ($($name,)+) = self;
                Ok(($($name.view(ctx)?,)+))
            }
        }
    };
}
tuple_inputs!(A);
tuple_inputs!(A, B);
tuple_inputs!(A, B, C);
tuple_inputs!(A, B, C, D);
tuple_inputs!(A, B, C, D, E);
tuple_inputs!(A, B, C, D, E, G);
tuple_inputs!(A, B, C, D, E, G, H);
tuple_inputs!(A, B, C, D, E, G, H, J);

/// What a node is, apart from its inputs and parameters: the stage, the algorithm and its
/// code version (all three are part of the key), and the node's name in reports, lock files
/// and `--set` (the stage's name unless given).
#[derive(Clone, Debug)]
pub struct NodeSpec {
    pub(crate) name: String,
    pub(crate) stage: Stage,
    pub(crate) algorithm: &'static str,
    pub(crate) version: u32,
    pub(crate) pieces: Option<PieceDecl>,
}

/// The declared key material of a node's pieces (see [`super::pieces`]).
#[derive(Clone, Debug)]
pub(crate) struct PieceDecl {
    pub name: &'static str,
    pub params: Vec<u8>,
}

impl NodeSpec {
    /// `version`: bump whenever the algorithm's output for the same inputs changes.
    pub fn new(stage: Stage, algorithm: &'static str, version: u32) -> Self {
        NodeSpec {
            name: stage.name().to_owned(),
            stage,
            algorithm,
            version,
            pieces: None,
        }
    }

    /// A node of `stage` running `algorithm` (a stage file's `NODE`).
    pub fn of(stage: Stage, algorithm: texsyn_core::algorithm::Algorithm) -> Self {
        NodeSpec::new(stage, algorithm.name, algorithm.version)
    }

    /// Names the node (default: its stage's name). Names are unique within a DAG.
    pub fn named(mut self, name: impl Into<String>) -> Self {
        self.name = name.into();
        self
    }

    /// The node caches parts of its result as pieces (the solid's bricks). A piece's key is
    /// built from `name`, the node's code version, `params` (the part of the node's
    /// parameters the pieces depend on), the content hashes of the inputs wrapped in
    /// [`Keyed`], what the computation adds when it opens the store, and the piece's own
    /// coordinates: so pieces are shared between nodes that differ only in what they leave
    /// out (a solid's request).
    pub fn pieces(mut self, name: &'static str, params: &impl serde::Serialize) -> Self {
        self.pieces = Some(PieceDecl {
            name,
            params: canonical_bytes(params),
        });
        self
    }
}

impl Dag {
    /// Reads and hashes an input file (the same path twice gives the same input). `role` is
    /// the config key that named it, for the error if it cannot be read.
    pub fn file(&mut self, path: &Path, role: &str) -> Result<FileHandle, std::io::Error> {
        match self.add_file(path, role)? {
            InputRef::File(index) => Ok(FileHandle { index }),
            InputRef::Node(_) => unreachable!("add_file returns a file input"),
        }
    }

    /// Declares a node. `compute` receives the node's context (progress, pieces), its
    /// parameters and the views of its inputs in the shape `inputs` has, and returns the
    /// output value, which the pipeline writes and stores. A node whose output is a
    /// [`crate::artifact::Bundle`] is exported into the run's output directory.
    pub fn node<P, I, F, C>(
        &mut self,
        spec: NodeSpec,
        params: P,
        inputs: I,
        compute: C,
    ) -> Handle<F>
    where
        P: serde::Serialize + Send + Sync + 'static,
        I: Inputs,
        F: Format,
        C: for<'a, 'c> Fn(&'c NodeContext<'a>, &'c P, I::View<'a>) -> Result<F, NodeError>
            + Send
            + Sync
            + 'static,
    {
        let mut declared = Vec::new();
        inputs.declare(false, &mut declared);
        // Wiring mistakes that would make pieces be reused for other inputs, or mark inputs
        // that nothing reads as keyed: caught when the DAG is built, not by a wrong result.
        let keyed = declared.iter().any(|d| d.keyed);
        assert_eq!(
            spec.pieces.is_some(),
            keyed,
            "{}: a node with pieces keys them by at least one Keyed input, and only such a node \
             has Keyed inputs",
            spec.name
        );
        if let Some(p) = &spec.pieces {
            let clash = self.nodes.iter().find(|n| {
                n.pieces.as_ref().is_some_and(|q| q.name == p.name)
                    && (n.algorithm, n.version) != (spec.algorithm, spec.version)
            });
            assert!(
                clash.is_none(),
                "{}: pieces named {:?} already belong to another algorithm or version",
                spec.name,
                p.name
            );
        }
        let node = Node {
            name: spec.name,
            stage: spec.stage,
            algorithm: spec.algorithm,
            version: spec.version,
            params: canonical_bytes(&params),
            params_json: serde_json::to_value(&params).unwrap_or(serde_json::Value::Null),
            inputs: declared.iter().map(|d| d.input).collect(),
            keyed: declared.iter().map(|d| d.keyed).collect(),
            pieces: spec.pieces,
            exports: F::KIND == crate::artifact::Kind::FileBundle,
            kind: F::KIND,
            compute: Box::new(move |ctx| {
                let mut cursor = InputCursor {
                    data: ctx.inputs.iter(),
                };
                let views = inputs.view(&mut cursor)?;
                let out = compute(ctx, &params, views)?;
                Ok(out.write())
            }),
        };
        let InputRef::Node(index) = self.add(node) else {
            unreachable!("add returns a node input")
        };
        Handle {
            index,
            _format: PhantomData,
        }
    }
}

/// Parameters with an optional tail that is left out of the key when absent: serialized as the
/// parameters alone without it and as the pair `(params, tail)` with it. A method uses it to
/// add a setting that only some configs have (the solid's regions) without changing the keys
/// of the configs that do not. People (graph, status, `--json`) see `{params, tail}`.
#[derive(Clone, Debug)]
pub struct WithTail<P, T>(pub P, pub Option<T>);

impl<P: serde::Serialize, T: serde::Serialize> serde::Serialize for WithTail<P, T> {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        match &self.1 {
            None => self.0.serialize(s),
            Some(t) if s.is_human_readable() => {
                serde_json::json!({ "params": &self.0, "tail": t }).serialize(s)
            }
            Some(t) => (&self.0, t).serialize(s),
        }
    }
}
