//! Named physical error patterns: subspaces of the model's parameter space in words (a link
//! translated rigidly, all base joints rotated about a socket, a target moved, ...), which
//! the identifiability analysis ([`crate::analysis::identifiability`]) names blind directions by. Each
//! instrument model contributes its own (`points::patterns`,
//! `tilts::patterns`).
use nalgebra::DVector;

/// A named physical error pattern: a subspace of the parameter space.
#[derive(Debug, Clone)]
pub struct Pattern {
    /// Words for it.
    pub description: String,
    /// Spanning vectors (parameter space, any scale).
    pub vectors: Vec<DVector<f64>>,
}
