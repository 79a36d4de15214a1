//! One selected object as the plane assignment sees it (`planes` assigns, `fragments` pairs
//! a niche's pieces by depth): the type both share, so neither imports the other's.

use crate::curve::MAX_CURVES;
use crate::real::Real;

/// One selected object and what the plane assignment needs of it.
#[derive(Debug, Clone, Copy)]
pub(super) struct Candidate {
    pub label: u16,
    pub min_x: u16,
    pub max_x: u16,
    pub mean_row: Real,
    pub pixels: u32,
    /// The plane whose curve it is, if any.
    pub plane: Option<usize>,
}

impl Candidate {
    pub(super) const NONE: Candidate = Candidate {
        label: 0,
        min_x: 0,
        max_x: 0,
        mean_row: 0.0,
        pixels: 0,
        plane: None,
    };
}

/// Most objects selected with [`super::PipelineConfig::stacks`] (wall mode): the assignment, not the
/// rank alone, decides which pieces are curves — a cable's two pieces near the central column
/// would otherwise crowd out a niche's front wall — and at most [`MAX_CURVES`] of them, the
/// nearest, are extracted.
pub(super) const MAX_CANDIDATES: usize = 2 * MAX_CURVES;
