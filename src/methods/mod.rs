//! The method table: every method of the crate, registered in one place.
//!
//! A method is a settings type that implements [`Method`] in its own solver
//! folder (e.g. [`ImplicitSolver`] in `solver/implicit/`). One line of the
//! `method_table!` below makes it
//!
//! - an ECS component (inserting it on a [`Cloth`] selects
//!   the method; a cloth has one method at a time),
//! - a plugin (`MethodPlugin<ItsType>`, with a named alias such as
//!   [`ImplicitPlugin`]) and a member of [`ClothPlugins`](crate::ClothPlugins),
//! - a variant of [`AnyMethod`], the by-value sum of every method that the
//!   inspector panel, the examples' command lines, the report, the stability
//!   map and the perf page sweep.
//!
//! [`PRESETS`] names the interactive settings of each method once (the
//! lab's 32 iterations and `ρ = 0.995`, the assignment's CG): the panel's
//! method list, the examples' `--method NAME`, the report and the perf page
//! all read them. A preset's name is its method's [`Method::name`], so a
//! method is named one way everywhere.
//!
//! Adding a method (`CONTRIBUTING.md` has the whole list): write
//! `solver/<method>/` with its settings type and its [`Method`] impl, add
//! one line to `method_table!`, its presets to [`PRESETS`], and its widgets
//! to the panel's exhaustive match (`ui/settings.rs`).

use core::any::{Any, TypeId};

mod plugin;

pub use plugin::{ClothMethod, ClothWorkspace, MethodPlugin};

use bevy::app::PluginGroupBuilder;
use bevy::ecs::component::{Component, Mutable, StorageType};
use bevy::ecs::intern::Interned;
use bevy::ecs::schedule::ScheduleLabel;
use bevy::ecs::world::EntityWorldMut;
use bevy::prelude::EntityCommands;
use bevy::prelude::{Entity, Query, Res, Time, warn};
use thiserror::Error;

use crate::collision::PenaltySphere;
use crate::ecs::{Cloth, ClothStats, ClothStatus};
use crate::model::{ClothModel, ClothState};
use crate::solver::exact::ExactSolver;
use crate::solver::implicit::ImplicitSolver;
use crate::solver::linear::{CgConfig, LinearImplicitSolver, SpringJacobian};
use crate::solver::pbd::PbdSolver;
use crate::solver::projective::{PD_ANDERSON_ITERATIONS, PD_ANDERSON_WINDOW, ProjectiveSolver};
use crate::solver::symplectic::SymplecticSolver;
use crate::solver::xpbd::XpbdSolver;
use crate::solver::{
    LAB_ITERATIONS, LAB_RHO, Method, ParamError, StepError, StepInput, StepParams, StepReport,
};

/// Generates, from one line per method: the component impl, the plugin
/// alias, the [`AnyMethod`] variant and its dispatch, and the plugin group's
/// list.
macro_rules! method_table {
    ($( $(#[$doc:meta])* $variant:ident($ty:ident) => $plugin:ident; )*) => {
        /// One method with its settings, by value: for code that sweeps or
        /// switches methods (the panel, command lines, the report).
        #[derive(Clone, Copy, Debug, PartialEq)]
        pub enum AnyMethod {
            $( $(#[$doc])* $variant($ty), )*
        }

        $(
            impl From<$ty> for AnyMethod {
                fn from(method: $ty) -> Self {
                    Self::$variant(method)
                }
            }

            /// A method component: on a [`Cloth`](crate::Cloth) entity it
            /// selects this method (see [`methods`](crate::methods)).
            impl Component for $ty {
                const STORAGE_TYPE: StorageType = StorageType::Table;
                type Mutability = Mutable;
            }

            #[doc = concat!("Steps the cloths that carry a [`", stringify!($ty), "`].")]
            pub type $plugin = MethodPlugin<$ty>;
        )*

        impl AnyMethod {
            /// The method's name ([`Method::name`]).
            pub fn name(&self) -> &'static str {
                match self { $( Self::$variant(m) => m.name(), )* }
            }

            /// Iterations per step of an iterative method.
            pub fn iterations(&self) -> Option<u32> {
                match self { $( Self::$variant(m) => m.iterations(), )* }
            }

            /// The same method with another iteration count.
            #[must_use]
            pub fn with_iterations(self, iterations: u32) -> Self {
                match self { $( Self::$variant(m) => Self::$variant(m.with_iterations(iterations)), )* }
            }

            /// Checks the settings.
            pub fn validate(&self) -> Result<(), ParamError> {
                match self { $( Self::$variant(m) => m.validate(), )* }
            }

            /// Whether the springs' stiffness acts ([`Method::uses_stiffness`]).
            pub fn uses_stiffness(&self) -> bool {
                match self { $( Self::$variant(m) => m.uses_stiffness(), )* }
            }

            /// Advances `state` by one step of this method, with its
            /// scratch in `ws`.
            pub fn step(
                &self,
                model: &ClothModel,
                state: &mut ClothState,
                params: &StepParams,
                spheres: &[PenaltySphere],
                ws: &mut AnyWorkspace,
            ) -> Result<StepReport, StepError> {
                match self {
                    $( Self::$variant(m) => m.step(model, state, params, spheres, ws.get::<<$ty as Method>::Workspace>()), )*
                }
            }

            /// [`step`](Self::step) with the whole [`StepInput`] (the
            /// solids projected after the step included, which the `stiff`
            /// method projects inside it).
            pub fn step_with(
                &self,
                input: StepInput<'_>,
                state: &mut ClothState,
                ws: &mut AnyWorkspace,
            ) -> Result<StepReport, StepError> {
                match self {
                    $( Self::$variant(m) => m.step_with(input, state, ws.get::<<$ty as Method>::Workspace>()), )*
                }
            }

            /// The [`TypeId`] of the settings type (the component), which
            /// [`ClothMethods`](crate::ClothMethods) lists once its plugin
            /// is added.
            pub fn type_id(&self) -> TypeId {
                match self { $( Self::$variant(_) => TypeId::of::<$ty>(), )* }
            }

            /// Inserts the method as a component (replacing the cloth's
            /// method, if it had one).
            pub fn insert(self, entity: &mut EntityCommands) {
                match self { $( Self::$variant(m) => { entity.insert(m); } )* }
            }

            /// [`insert`](Self::insert) with direct world access.
            pub fn insert_now(self, entity: &mut EntityWorldMut) {
                match self { $( Self::$variant(m) => { entity.insert(m); } )* }
            }

            /// The method of a query item of [`AnyMethodData`], if the
            /// entity has one.
            #[allow(non_snake_case)]
            pub fn from_item(item: ( $( Option<&$ty>, )* )) -> Option<Self> {
                let ( $( $variant, )* ) = item;
                $( if let Some(m) = $variant { return Some(Self::$variant(*m)); } )*
                None
            }
        }

        /// Query data that reads whichever method component an entity has
        /// ([`AnyMethod::from_item`]); read-only, so it never conflicts with
        /// queries of the cloth's other components.
        pub type AnyMethodData = ( $( Option<&'static $ty>, )* );

        /// Adds every method's plugin to `group`.
        pub(crate) fn add_method_plugins(
            group: PluginGroupBuilder,
            schedule: Interned<dyn ScheduleLabel>,
        ) -> PluginGroupBuilder {
            group $( .add($plugin::new(schedule)) )*
        }
    };
}

method_table! {
    /// Implicit Euler by Jacobi or Chebyshev iterations (the lab's part 1).
    Implicit(ImplicitSolver) => ImplicitPlugin;
    /// Position-based strain limiting (the lab's part 2).
    Pbd(PbdSolver) => PbdPlugin;
    /// Symplectic Euler (the assignment's first stage).
    Symplectic(SymplecticSolver) => SymplecticPlugin;
    /// Linearly implicit Euler, sparse CG or LDLᵀ (the assignment).
    Linear(LinearImplicitSolver) => LinearImplicitPlugin;
    /// Projective dynamics (local–global), Chebyshev-accelerated.
    Projective(ProjectiveSolver) => ProjectivePlugin;
    /// Exact implicit Euler: Newton to a gradient tolerance (the reference).
    Exact(ExactSolver) => ExactPlugin;
    /// XPBD with small steps, contacts in every substep (the `stiff` preset).
    Xpbd(XpbdSolver) => XpbdPlugin;
}

impl Default for AnyMethod {
    /// The preset for a game: `stiff` ([`XpbdSolver::STIFF`]), which keeps
    /// cloth of real mass and stiff cloth in contact at its length at a
    /// frame rate (the lab's examples keep the lab's `chebyshev`).
    fn default() -> Self {
        Self::Xpbd(XpbdSolver::STIFF)
    }
}

/// A named setting of a method: what the panel lists and `--method NAME`
/// selects.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Preset {
    /// A label for menus.
    pub label: &'static str,
    /// The method and its settings.
    pub method: AnyMethod,
}

impl Preset {
    /// The preset's name: its method's [`Method::name`].
    pub fn name(&self) -> &'static str {
        self.method.name()
    }
}

/// Every method at its interactive settings, in menu order: 32 iterations
/// for the iterative lab methods (Chebyshev with the lab's `ρ = 0.995`, or
/// estimated), the assignment's CG (25 iterations, 1e-6), the linearly
/// implicit methods with compression-clamped spring blocks (the
/// assignment's exact blocks make the lab cloth's matrix indefinite),
/// projective dynamics (10 Chebyshev or 20 Anderson iterations), Newton on
/// a budget ([`ExactSolver::BUDGET`]: 16 iterations, tolerance 1e-5),
/// the exact method at the reference tolerance, and XPBD at 960 substeps
/// per second with tethers ([`XpbdSolver::STIFF`], `stiff`).
pub const PRESETS: &[Preset] = &[
    Preset {
        label: "Implicit (Jacobi)",
        method: AnyMethod::Implicit(ImplicitSolver::jacobi(LAB_ITERATIONS)),
    },
    Preset {
        label: "Implicit (Chebyshev)",
        method: AnyMethod::Implicit(ImplicitSolver::chebyshev(LAB_ITERATIONS, LAB_RHO)),
    },
    Preset {
        label: "Implicit (Chebyshev, ρ estimated)",
        method: AnyMethod::Implicit(ImplicitSolver::chebyshev_auto(LAB_ITERATIONS)),
    },
    Preset {
        label: "PBD (strain limiting)",
        method: AnyMethod::Pbd(PbdSolver::new(LAB_ITERATIONS)),
    },
    Preset {
        label: "Symplectic Euler",
        method: AnyMethod::Symplectic(SymplecticSolver),
    },
    Preset {
        label: "Linearly implicit (CG)",
        method: AnyMethod::Linear(
            LinearImplicitSolver::cg(CgConfig::ASSIGNMENT)
                .with_springs(SpringJacobian::ClampCompression),
        ),
    },
    Preset {
        label: "Linearly implicit (direct)",
        method: AnyMethod::Linear(
            LinearImplicitSolver::direct().with_springs(SpringJacobian::ClampCompression),
        ),
    },
    Preset {
        label: "Projective dynamics (Chebyshev)",
        method: AnyMethod::Projective(ProjectiveSolver::PRESET),
    },
    Preset {
        label: "Projective dynamics (Anderson, stiff cloth)",
        method: AnyMethod::Projective(ProjectiveSolver::anderson(
            PD_ANDERSON_ITERATIONS,
            PD_ANDERSON_WINDOW,
        )),
    },
    Preset {
        label: "Newton on a budget (stiff cloth)",
        method: AnyMethod::Exact(ExactSolver::BUDGET),
    },
    Preset {
        label: "Exact implicit (Newton)",
        method: AnyMethod::Exact(ExactSolver::REFERENCE),
    },
    Preset {
        label: "Stiff cloth (XPBD, 960 substeps/s)",
        method: AnyMethod::Xpbd(XpbdSolver::STIFF),
    },
];

/// A method name that no preset has.
#[derive(Error, Debug, Clone, PartialEq, Eq)]
#[error("unknown method '{0}' (known: {known})", known = preset_names().join(", "))]
pub struct UnknownMethod(pub String);

impl From<UnknownMethod> for String {
    fn from(e: UnknownMethod) -> Self {
        e.to_string()
    }
}

/// The names of [`PRESETS`], in order.
pub fn preset_names() -> Vec<&'static str> {
    PRESETS.iter().map(Preset::name).collect()
}

/// The preset named `name` (`"implicit"` is accepted for `"jacobi"`, the
/// lab's part 1).
pub fn preset(name: &str) -> Result<&'static Preset, UnknownMethod> {
    let name = if name == "implicit" { "jacobi" } else { name };
    PRESETS
        .iter()
        .find(|p| p.name() == name)
        .ok_or_else(|| UnknownMethod(name.to_owned()))
}

impl core::str::FromStr for AnyMethod {
    type Err = UnknownMethod;

    /// The method of the preset named `s` (see [`preset`]).
    fn from_str(s: &str) -> Result<Self, UnknownMethod> {
        preset(s).map(|p| p.method)
    }
}

/// Every method's scratch buffers for [`AnyMethod::step`], each allocated on
/// its method's first step and kept while the workspace lives.
#[derive(Default)]
pub struct AnyWorkspace {
    slots: Vec<(TypeId, Box<dyn Any + Send + Sync>)>,
}

impl AnyWorkspace {
    /// The workspace of type `W`, created on first use.
    pub fn get<W: Default + Send + Sync + 'static>(&mut self) -> &mut W {
        let id = TypeId::of::<W>();
        let i = match self.slots.iter().position(|(t, _)| *t == id) {
            Some(i) => i,
            None => {
                self.slots.push((id, Box::new(W::default())));
                self.slots.len() - 1
            }
        };
        self.slots[i]
            .1
            .downcast_mut()
            .expect("a slot holds the type it is keyed by")
    }
}

impl core::fmt::Debug for AnyWorkspace {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("AnyWorkspace")
            .field("workspaces", &self.slots.len())
            .finish()
    }
}

/// Marks each cloth that no method stepped this time step as
/// [`ClothStatus::NoMethod`], naming its method if it has one (whose plugin
/// is then missing from the app), and warns once per change. Added by the
/// first method plugin, beside the method table that names every method.
pub(crate) fn report_unclaimed(
    time: Res<Time>,
    mut cloths: Query<(Entity, &Cloth, &mut ClothStats, AnyMethodData)>,
) {
    if time.delta_secs_f64() <= 0.0 {
        return;
    }
    for (entity, cloth, mut stats, method) in &mut cloths {
        if cloth.claimed {
            continue;
        }
        let method = AnyMethod::from_item(method).map(|m| m.name());
        if stats.status != (ClothStatus::NoMethod { method }) {
            match method {
                Some(name) => warn!(
                    "cloth {entity} is not simulated: its method '{name}' has no plugin \
                     in this app; add its plugin (or `ClothPlugins`)"
                ),
                None => warn!(
                    "cloth {entity} is not simulated: it has no method component; \
                     insert one, e.g. `ImplicitSolver::default()`"
                ),
            }
            stats.status = ClothStatus::NoMethod { method };
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_round_trip_and_bad_names_are_refused() {
        for p in PRESETS {
            assert_eq!(preset(p.name()).map(|q| q.method), Ok(p.method));
            assert_eq!(p.name().parse::<AnyMethod>(), Ok(p.method));
        }
        assert_eq!(preset("implicit").unwrap().name(), "jacobi");
        let err = "verlet".parse::<AnyMethod>().unwrap_err().to_string();
        assert!(err.contains("unknown method 'verlet'") && err.contains("linear-direct"));
        // One name per preset.
        let mut names = preset_names();
        names.sort_unstable();
        names.dedup();
        assert_eq!(names.len(), PRESETS.len());
    }
}
