//! Wind and air drag as a resource, a component and a plugin.

use bevy::prelude::*;
use bevy::utils::Parallel;

use super::{Cloth, ClothCorePlugin, ClothSchedule, ClothStats, ClothSystems};
use crate::aero::{AeroCoefficients, AeroWorkspace, WindField, apply_air};

/// The wind every cloth is in: a mean velocity with deterministic gusts
/// ([`WindField`]). Insert it (with [`WindPlugin`], part of
/// [`ClothPlugins`](crate::ClothPlugins)) to give every cloth air drag and
/// lift ([`ClothAerodynamics`]); `Wind::default()` is still air: drag only.
/// Without this resource no air acts and the wind system does not run.
///
/// Change it at any time (a gust, a storm): the next fixed step uses it.
/// Gusts follow the fixed clock, so the same scene gives the same wind run
/// after run. Invalid values (non-finite velocity, negative turbulence, a
/// period not above zero) stop the wind with a warning until they are
/// fixed.
#[derive(Resource, Reflect, Clone, Copy, Debug, PartialEq)]
#[reflect(Resource, Debug, PartialEq, Default)]
pub struct Wind {
    /// Mean wind velocity (m/s, world space).
    pub velocity: Vec3,
    /// Gust strength as a fraction of the mean speed (0: steady). The speed
    /// along the wind varies by up to this fraction, across it by half.
    pub turbulence: f32,
    /// The longest gust's period in seconds.
    pub gust_period: f32,
    /// Picks the gusts (same seed, same gusts).
    pub seed: u64,
}

impl Default for Wind {
    /// Still air.
    fn default() -> Self {
        Self::new(Vec3::ZERO)
    }
}

impl Wind {
    /// A steady wind of this velocity (gust period 2 s once turbulence is set).
    pub const fn new(velocity: Vec3) -> Self {
        Self {
            velocity,
            turbulence: 0.0,
            gust_period: 2.0,
            seed: 0,
        }
    }

    /// The same wind with gusts of this strength.
    #[must_use]
    pub const fn with_turbulence(mut self, turbulence: f32) -> Self {
        self.turbulence = turbulence;
        self
    }

    /// The numerical field.
    pub fn field(&self) -> WindField {
        WindField {
            velocity: self.velocity.into(),
            turbulence: self.turbulence,
            gust_period: self.gust_period,
            seed: self.seed,
        }
    }
}

/// How a cloth meets the air (optional: a cloth without it uses the
/// defaults, sea-level air, `C_d = 1`, `C_l = 0.5`). Forces per triangle as
/// in [`aero`](crate::aero). Negative or non-finite values skip the cloth's
/// air forces with a warning.
#[derive(Component, Reflect, Clone, Copy, Debug, PartialEq)]
#[reflect(Component, Debug, PartialEq, Default)]
pub struct ClothAerodynamics {
    /// Air density `ρ` (kg/m³).
    pub air_density: f32,
    /// Drag coefficient `C_d`.
    pub drag: f32,
    /// Lift coefficient `C_l`.
    pub lift: f32,
}

impl Default for ClothAerodynamics {
    fn default() -> Self {
        let c = AeroCoefficients::default();
        Self {
            air_density: c.air_density,
            drag: c.drag,
            lift: c.lift,
        }
    }
}

impl ClothAerodynamics {
    /// The numerical coefficients.
    pub fn coefficients(&self) -> AeroCoefficients {
        AeroCoefficients {
            air_density: self.air_density,
            drag: self.drag,
            lift: self.lift,
        }
    }
}

scheduled_plugin! {
    /// Adds wind and air: while a [`Wind`] resource exists, every running cloth
    /// gets per-triangle drag and lift in [`ClothSystems::Forces`], before its
    /// method steps, as an explicit external force (so for every method).
    WindPlugin
}

impl Plugin for WindPlugin {
    fn build(&self, app: &mut App) {
        ClothCorePlugin::new_interned(self.schedule).add_once(app);
        app.register_type::<Wind>()
            .register_type::<ClothAerodynamics>()
            .add_systems(
                ClothSchedule,
                blow.in_set(ClothSystems::Forces)
                    .run_if(resource_exists::<Wind>.and_then(any_with_component::<Cloth>)),
            );
    }
}

/// What [`blow`] keeps between runs: scratch per thread, and what it warned
/// about.
#[derive(Default)]
struct BlowMemory {
    scratch: Parallel<AeroWorkspace>,
    refused: Parallel<Vec<Entity>>,
    warned: Vec<Entity>,
    wind_warned: bool,
}

/// Applies the air forces of this step to every running cloth.
fn blow(
    time: Res<Time>,
    wind: Res<Wind>,
    mut cloths: Query<(Entity, &mut Cloth, &ClothStats, Option<&ClothAerodynamics>)>,
    mut memory: Local<BlowMemory>,
) {
    let dt = time.delta_secs();
    if dt <= 0.0 {
        return;
    }
    let field = wind.field();
    if let Err(error) = field.validate() {
        if !memory.wind_warned {
            warn!("the wind is off: {error}");
            memory.wind_warned = true;
        }
        return;
    }
    memory.wind_warned = false;
    // The wind as it is at the start of this step.
    let t = time.elapsed_secs_f64() - time.delta_secs_f64();
    let BlowMemory {
        scratch, refused, ..
    } = &mut *memory;
    for_each_cloth!(cloths, |(entity, mut cloth, stats, aero)| {
        if !cloth.initialized || !stats.is_running() {
            return;
        }
        let coefficients = aero.copied().unwrap_or_default().coefficients();
        if coefficients.validate().is_err() {
            refused.borrow_local_mut().push(entity);
            return;
        }
        let cloth = &mut *cloth;
        apply_air(
            &cloth.model,
            &mut cloth.state,
            &coefficients,
            |x| field.at(x, t),
            dt,
            &mut scratch.borrow_local_mut(),
        );
    });
    let mut refused: Vec<Entity> = memory.refused.drain().collect();
    refused.sort();
    for entity in refused {
        if !memory.warned.contains(&entity) {
            let aero = cloths.get(entity).ok().and_then(|(_, _, _, a)| a.copied());
            if let Some(Err(error)) = aero.map(|a| a.coefficients().validate()) {
                warn!("cloth {entity} gets no air forces: {error}");
            }
            memory.warned.push(entity);
        }
    }
}
