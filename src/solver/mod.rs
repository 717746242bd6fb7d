//! Pure numerics: a folder per method, one entry point each, over the engine room. No ECS types.
//!
//! Every method ([`Method::step`], its one entry point) advances a [`ClothState`](crate::model::ClothState) by one time step of a
//! [`ClothModel`](crate::model::ClothModel) under [`StepParams`], using a method-specific workspace that
//! is allocated on the first step and reused afterwards (no allocation per
//! step once the sizes are known).
//!
//! Each method is a settings type implementing [`Method`], in its own folder
//! (or file) holding everything that is only that method's:
//!
//! | settings ([`Method`]) | method | file | spec |
//! |---|---|---|---|
//! | [`ImplicitSolver`](implicit::ImplicitSolver) | implicit Euler, diagonal-Hessian Newton (Jacobi), optional Chebyshev | [`implicit`] | lab part 1 |
//! | [`PbdSolver`](pbd::PbdSolver) | position-based dynamics, Jacobi strain limiting | [`pbd`] | lab part 2 |
//! | [`SymplecticSolver`](symplectic::SymplecticSolver) | symplectic Euler (`A = M`) | [`symplectic`] | the assignment's first stage |
//! | [`LinearImplicitSolver`](linear::LinearImplicitSolver) | linearly implicit Euler (`A = M − h²K`), sparse CG or LDLᵀ | [`linear`] | the assignment |
//! | [`ProjectiveSolver`](projective::ProjectiveSolver) | projective dynamics (local–global) on the implicit-Euler objective, Chebyshev-accelerated | [`projective`] | Liu et al. 2013, Wang 2015 |
//! | [`ExactSolver`](exact::ExactSolver) | exact implicit Euler: Newton + sparse Cholesky + line search (to 1e-9, or on a budget: `newton`) | [`exact`] | the reference |
//! | [`XpbdSolver`](xpbd::XpbdSolver) | XPBD with small steps: substeps of one Gauss–Seidel sweep, contacts in every substep (`stiff`) | [`xpbd`] | Macklin et al. 2016, 2019 |
//!
//! Penalty spheres ([`PenaltySphere`](crate::collision::PenaltySphere)) act
//! inside every step: as forces with their stiffness in the linear system
//! (linearly implicit), in the gradient and diagonal (implicit Jacobi), or
//! as explicit forces (symplectic, and PBD's and XPBD's velocity
//! prediction). The solids projected after the step
//! ([`StepInput::contacts`]) are projected inside every substep by XPBD.
//!
//! The divergence guard ([`guard`]) checks a step and retries it with
//! halved time steps when it fails.
//!
//! Shared parts: [`params`] (what a step takes and returns), [`method`]
//! (the trait), [`measures`] ([`objective`], [`gradient`], [`max_stretch`],
//! [`energy`], [`measure`], [`step_error`], [`ConvergenceSums`]),
//! [`chebyshev`] (the acceleration the implicit iteration and projective
//! dynamics share) and the engine room (`engine`, hidden from the docs: the
//! SIMD spring passes, the grid kernels, the parallel phases and the sparse
//! factorisation; the only module with `unsafe` code).

pub mod chebyshev;
#[doc(hidden)]
#[allow(unsafe_code)]
pub mod engine;
pub mod exact;
pub mod guard;
pub mod implicit;
pub mod linear;
pub mod measures;
pub mod method;
pub mod params;
pub mod pbd;
pub mod projective;
#[doc(hidden)]
pub mod springs;
pub mod symplectic;
pub mod xpbd;

pub use engine::kernels::PARALLEL_MIN;
pub use engine::simd::Simd;
pub use measures::{
    ContactError, ConvergenceSums, Measured, ProjectedConvergence, energy, gradient, max_stretch,
    measure, objective, step_error,
};
pub use method::{LAB_ITERATIONS, LAB_RHO, Method, SkinInput, StepInput};
pub use params::{
    CONVERGENCE_TOLERANCE, ParamError, SolveError, SpringStiffness, StepError, StepParams,
    StepReport,
};

#[cfg(test)]
mod tests;
