//! Every method by name, for command lines, menus and scripts.

use core::str::FromStr;

use bevy::prelude::*;

use super::{ExactSolver, ImplicitSolver, LinearImplicitSolver, PbdSolver, SymplecticSolver};
use crate::solver::linear::{CgConfig, SpringJacobian};

/// One of the crate's methods, named as [`ClothStats::method`](super::ClothStats::method)
/// names them. Parse one from text (`"chebyshev".parse()`), list them all
/// ([`ALL`](Self::ALL)), or insert one on a cloth with interactive defaults
/// ([`insert`](Self::insert)).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum MethodChoice {
    /// Implicit Euler, plain Jacobi (the lab's 1.c).
    Jacobi,
    /// Implicit Euler, Chebyshev-accelerated Jacobi (the lab's 1.d).
    Chebyshev,
    /// Position-based dynamics (the lab's part 2).
    Pbd,
    /// Symplectic Euler (the assignment's first stage).
    Symplectic,
    /// Linearly implicit Euler with conjugate gradients.
    LinearCg,
    /// Linearly implicit Euler with the direct sparse solve.
    LinearDirect,
    /// Exact implicit Euler (Newton).
    Exact,
}

impl MethodChoice {
    /// Every method, in menu order.
    pub const ALL: [Self; 7] = [
        Self::Jacobi,
        Self::Chebyshev,
        Self::Pbd,
        Self::Symplectic,
        Self::LinearCg,
        Self::LinearDirect,
        Self::Exact,
    ];

    /// The short name (`"jacobi"`, `"chebyshev"`, `"pbd"`, `"symplectic"`,
    /// `"linear-cg"`, `"linear-direct"`, `"exact"`).
    pub fn name(self) -> &'static str {
        match self {
            Self::Jacobi => "jacobi",
            Self::Chebyshev => "chebyshev",
            Self::Pbd => "pbd",
            Self::Symplectic => "symplectic",
            Self::LinearCg => "linear-cg",
            Self::LinearDirect => "linear-direct",
            Self::Exact => "exact",
        }
    }

    /// A label for menus.
    pub fn label(self) -> &'static str {
        match self {
            Self::Jacobi => "Implicit (Jacobi)",
            Self::Chebyshev => "Implicit (Chebyshev)",
            Self::Pbd => "PBD (strain limiting)",
            Self::Symplectic => "Symplectic Euler",
            Self::LinearCg => "Linearly implicit (CG)",
            Self::LinearDirect => "Linearly implicit (direct)",
            Self::Exact => "Exact implicit (Newton)",
        }
    }

    /// The [`ClothMethod::KIND`](super::ClothMethod::KIND) of the plugin that
    /// steps it (see [`ClothMethods`](super::ClothMethods)).
    pub fn kind(self) -> &'static str {
        match self {
            Self::Jacobi | Self::Chebyshev => "implicit",
            Self::Pbd => "pbd",
            Self::Symplectic => "symplectic",
            Self::LinearCg | Self::LinearDirect => "linear-implicit",
            Self::Exact => "exact",
        }
    }

    /// Inserts the method's component with interactive defaults: 32
    /// iterations (Chebyshev ρ = 0.995), CG with the assignment's settings,
    /// and, for the linearly implicit methods, compression-clamped spring
    /// blocks (the assignment's exact ones make the lab cloth's matrix
    /// indefinite).
    pub fn insert(self, entity: &mut EntityCommands) {
        match self {
            Self::Jacobi => entity.insert(ImplicitSolver::jacobi(32)),
            Self::Chebyshev => entity.insert(ImplicitSolver::chebyshev(32, 0.995)),
            Self::Pbd => entity.insert(PbdSolver::default()),
            Self::Symplectic => entity.insert(SymplecticSolver),
            Self::LinearCg => entity.insert(
                LinearImplicitSolver::cg(CgConfig::default())
                    .with_springs(SpringJacobian::ClampCompression),
            ),
            Self::LinearDirect => entity.insert(
                LinearImplicitSolver::direct().with_springs(SpringJacobian::ClampCompression),
            ),
            Self::Exact => entity.insert(ExactSolver::default()),
        };
    }
}

impl FromStr for MethodChoice {
    type Err = String;

    /// Parses a [`name`](Self::name); `"implicit"` means Jacobi.
    fn from_str(s: &str) -> Result<Self, String> {
        if s == "implicit" {
            return Ok(Self::Jacobi);
        }
        Self::ALL
            .into_iter()
            .find(|m| m.name() == s)
            .ok_or_else(|| {
                let names: Vec<&str> = Self::ALL.iter().map(|m| m.name()).collect();
                format!(
                    "unknown method '{s}' (known: implicit, {})",
                    names.join(", ")
                )
            })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_round_trip_and_bad_names_are_refused() {
        for m in MethodChoice::ALL {
            assert_eq!(m.name().parse::<MethodChoice>(), Ok(m));
        }
        assert_eq!("implicit".parse::<MethodChoice>(), Ok(MethodChoice::Jacobi));
        let err = "newton".parse::<MethodChoice>().unwrap_err();
        assert!(err.contains("unknown method 'newton'") && err.contains("linear-direct"));
    }
}
