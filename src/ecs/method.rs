//! The glue every method plugin shares: one generic step system, and the rule
//! that a cloth has at most one method component at a time.

use core::any::type_name;
use std::time::Instant;

use bevy::ecs::component::{ComponentId, Mutable};
use bevy::ecs::intern::Interned;
use bevy::ecs::schedule::ScheduleLabel;
use bevy::ecs::schedule::common_conditions::any_with_component;
use bevy::prelude::*;

use super::{Cloth, ClothParams, ClothStats, ClothStatus, ClothSystems};
use crate::model::{ClothModel, ClothState};
use crate::solver::{StepError, StepParams, StepReport};

/// A simulation method: a component whose presence on a [`Cloth`] entity
/// selects how that cloth is stepped.
///
/// A cloth has at most one method: inserting one removes any other, so
/// swapping the component switches the method at run time. Each method's
/// scratch buffers live in a [`ClothWorkspace`] that is added with the
/// method and removed with it.
pub trait ClothMethod: Component<Mutability = Mutable> {
    /// Short name, shown in [`ClothStats::method`] and messages.
    const NAME: &'static str;
    /// Scratch buffers reused from step to step.
    type Workspace: Default + Send + Sync + 'static;

    /// Advances `state` by one step.
    fn step(
        &self,
        model: &ClothModel,
        state: &mut ClothState,
        params: &StepParams,
        workspace: &mut Self::Workspace,
    ) -> Result<StepReport, StepError>;
}

/// A method's scratch buffers on a cloth entity (not reflected: it holds no
/// state worth inspecting and is rebuilt on demand).
#[derive(Component, Default, Debug)]
pub struct ClothWorkspace<W: Default + Send + Sync + 'static>(pub W);

/// The method components registered by method plugins, for the
/// one-method-per-cloth rule.
#[derive(Resource, Default, Debug)]
pub struct ClothMethods {
    ids: Vec<(ComponentId, &'static str)>,
}

impl ClothMethods {
    /// Names of the registered methods, in registration order.
    pub fn names(&self) -> impl Iterator<Item = &'static str> + '_ {
        self.ids.iter().map(|&(_, name)| name)
    }
}

/// The step systems of all methods.
#[derive(SystemSet, Debug, Clone, Copy, PartialEq, Eq, Hash)]
struct MethodSteps;

/// Registers method `M`: its step system in [`ClothSystems::Step`] (running
/// only while some entity has `M`), and the observers that keep one method
/// per cloth and manage `M`'s workspace.
pub(crate) fn add_method<M: ClothMethod>(app: &mut App, schedule: Interned<dyn ScheduleLabel>) {
    let id = app.world_mut().register_component::<M>();
    let mut methods = app.world_mut().get_resource_or_init::<ClothMethods>();
    if methods.ids.iter().any(|&(i, _)| i == id) {
        return;
    }
    methods.ids.push((id, M::NAME));
    app.add_systems(
        schedule,
        step_cloths::<M>
            .in_set(ClothSystems::Step)
            .in_set(MethodSteps)
            // Method step systems all write `Cloth`, but never the same cloth:
            // a cloth has one method (enforced by the observers below).
            .ambiguous_with(MethodSteps)
            .run_if(any_with_component::<M>),
    )
    .add_observer(on_method_inserted::<M>)
    .add_observer(on_method_removed::<M>);
}

fn on_method_inserted<M: ClothMethod>(
    insert: On<Insert, M>,
    methods: Res<ClothMethods>,
    entities: Query<EntityRef>,
    mut commands: Commands,
) {
    let entity = insert.entity;
    let Ok(entity_ref) = entities.get(entity) else {
        return;
    };
    let mut cmds = commands.entity(entity);
    for &(id, name) in &methods.ids {
        if name != M::NAME && entity_ref.contains_id(id) {
            cmds.remove_by_id(id);
        }
    }
    if !entity_ref.contains::<ClothWorkspace<M::Workspace>>() {
        cmds.insert(ClothWorkspace::<M::Workspace>::default());
    }
}

fn on_method_removed<M: ClothMethod>(remove: On<Remove, M>, mut commands: Commands) {
    if let Ok(mut e) = commands.get_entity(remove.entity) {
        e.try_remove::<ClothWorkspace<M::Workspace>>();
    }
}

/// What the step system of method `M` reads and writes per cloth.
type StepData<M> = (
    Entity,
    &'static mut Cloth,
    &'static ClothParams,
    &'static M,
    &'static mut ClothWorkspace<<M as ClothMethod>::Workspace>,
    &'static mut ClothStats,
);

/// Steps every running cloth that has method `M`, in parallel across cloths.
fn step_cloths<M: ClothMethod>(time: Res<Time>, mut cloths: Query<StepData<M>>) {
    let dt = time.delta_secs();
    if dt <= 0.0 {
        return;
    }
    cloths
        .par_iter_mut()
        .for_each(|(entity, mut cloth, params, method, mut ws, mut stats)| {
            if !cloth.initialized || matches!(stats.status, ClothStatus::Diverged(_)) {
                return;
            }
            let cloth = &mut *cloth;
            cloth.last_good.copy_from(&cloth.state);
            let params = params.step_params(dt);
            let start = Instant::now();
            let result = method.step(&cloth.model, &mut cloth.state, &params, &mut ws.0);
            let elapsed = start.elapsed();
            match result {
                Ok(report) => {
                    stats.method = M::NAME;
                    stats.steps += 1;
                    stats.step_time = elapsed;
                    stats.iterations = report.iterations;
                    stats.residual = report.residual;
                    if !stats.is_running() {
                        stats.status = ClothStatus::Running;
                    }
                }
                Err(error) => {
                    let text = error.to_string();
                    if stats.status != ClothStatus::Invalid(text.clone()) {
                        warn!(
                            "cloth {entity} ({}) skipped: {text}",
                            type_name::<M>().rsplit("::").next().unwrap_or(M::NAME)
                        );
                        stats.status = ClothStatus::Invalid(text);
                    }
                }
            }
        });
}
