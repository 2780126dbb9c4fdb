//! Graphs given as compressed lists: [`Csr`], the count / prefix-sum / fill builder of
//! compressed adjacency, and [`Dijkstra`], the deterministic shortest-path search the mesh
//! code and the stages share. Neither knows about meshes or matrices, so both `geom` and
//! `linalg` use them without using each other.

pub mod csr;
pub mod dijkstra;

pub use csr::{Csr, for_each_run};
pub use dijkstra::Dijkstra;
