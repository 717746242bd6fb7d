//! The engine room: the fast machinery the methods share, and the only
//! place in the crate with `unsafe` code (the crate denies it elsewhere).
//!
//! - [`simd`]: the SIMD levels ([`Simd`](simd::Simd)), resolved against the
//!   CPU at run time, and the spring pass at each level;
//! - [`kernels`]: the general spring pass over any spring list, the padded
//!   per-vertex gathers, and the fixed-chunk (optionally parallel) loops;
//! - `phases`: one parallel region per iteration, in phases;
//! - `stencil`: the grid kernels (structure-of-arrays) of the implicit
//!   iteration, symplectic Euler, projective dynamics' local step and PBD's
//!   strain limiting, for cloths whose springs form a
//!   [`Stencil`](crate::model::ClothTopology);
//! - `sweep`: XPBD's Gauss–Seidel sweep over coloured springs, batched
//!   within a colour;
//! - `chain_lanes`: XPBD's chains of stretch springs solved whole, eight
//!   chains that share no vertex at a time;
//! - `cholesky`, `lane_factor`, `supernodal`: the sparse factorisation the
//!   direct methods share and its two triangular-solve layouts.
//!
//! The module is public but hidden from the docs: the report, the
//! benchmarks and the perf page measure its parts; a game never needs it.

pub(crate) mod chain_lanes;
pub(crate) mod cholesky;
pub mod kernels;
pub(crate) mod lane_factor;
pub(crate) mod phases;
pub mod simd;
pub(crate) mod stencil;
pub(crate) mod supernodal;
pub(crate) mod sweep;
