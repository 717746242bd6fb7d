//! A cloth's dynamic state as a value a game can save: [`ClothSnapshot`].

use bevy::math::Vec3A;
use bevy::reflect::Reflect;
use bevy::reflect::std_traits::ReflectDefault;

use super::Cloth;
use crate::solver::StepError;
use crate::solver::guard::GuardMemory;

/// Everything of a cloth that changes as it steps: positions, velocities,
/// where its pins were after the last step (a pin's velocity at the next
/// one), and the guard's memory of halved steps. The model (topology,
/// masses, pins) is not in it: a game rebuilds the cloth as it built it,
/// then restores the snapshot, and the cloth continues bitwise as if it had
/// never been saved.
///
/// `Reflect`, so it can live in a component or resource of a saved scene;
/// with the `serialize` feature also serde's `Serialize` and `Deserialize`
/// (`f32` round-trips exactly through text formats that print the
/// shortest exact form, as `serde_json` and `ron` do).
///
/// ```
/// use bevy::prelude::*;
/// use bevy_cloth::prelude::*;
///
/// let mut cloth = Cloth::build(ClothBuilder::lab()).unwrap();
/// // Placed (as its entity's insertion does).
/// cloth.reset_at(&GlobalTransform::IDENTITY);
/// let saved = cloth.snapshot();
/// assert_eq!(saved.positions.len(), 441);
/// assert!(cloth.restore_snapshot(&saved).is_ok());
/// // Another cloth's snapshot is refused, and the cloth keeps its state.
/// let mut other = Cloth::build(ClothBuilder::lab_grid(5)).unwrap();
/// assert!(matches!(
///     other.restore_snapshot(&saved),
///     Err(StepError::StateMismatch { expected: 25, got: 441 })
/// ));
/// ```
#[derive(Reflect, Clone, Debug, Default, PartialEq)]
#[reflect(Debug, PartialEq, Default)]
#[cfg_attr(feature = "serialize", derive(serde::Serialize, serde::Deserialize))]
pub struct ClothSnapshot {
    /// Vertex positions (world space).
    pub positions: Vec<[f32; 3]>,
    /// Vertex velocities.
    pub velocities: Vec<[f32; 3]>,
    /// The pinned vertices when it was taken (attachments' included): a
    /// snapshot restores only into a cloth with the same pins.
    pub pins: Vec<u32>,
    /// Each pin and where the last step left it.
    pub pins_stepped: Vec<(u32, [f32; 3])>,
    /// The guard's halvings of the next step.
    pub halvings: u8,
    /// Steps in a row that passed at the current halving.
    pub calm_steps: u32,
    /// The guard's [`recovering`](GuardMemory::recovering).
    #[cfg_attr(feature = "serialize", serde(default))]
    pub recovering: bool,
}

impl Cloth {
    /// The cloth's dynamic state, to save ([`ClothSnapshot`]).
    pub fn snapshot(&self) -> ClothSnapshot {
        let array = |v: &Vec3A| v.to_array();
        ClothSnapshot {
            positions: self.state.positions.iter().map(array).collect(),
            velocities: self.state.velocities.iter().map(array).collect(),
            pins: self.model.pins().to_vec(),
            pins_stepped: self
                .pins_stepped
                .iter()
                .map(|&(p, x)| (p, x.to_array()))
                .collect(),
            halvings: self.guard_memory.halvings,
            calm_steps: self.guard_memory.calm_steps,
            recovering: self.guard_memory.recovering,
        }
    }

    /// Puts back a [`snapshot`](Self::snapshot): the cloth continues from it
    /// at its next step, where it is. A snapshot of another cloth is a typed
    /// error and the cloth keeps its state:
    /// [`StepError::StateMismatch`] for another vertex count (or a snapshot
    /// whose lists disagree), [`StepError::PinsMismatch`] for other pins, or
    /// a position, velocity or pin index that is not finite or not a vertex
    /// ([`StepError::InvalidSnapshot`]).
    pub fn restore_snapshot(&mut self, snapshot: &ClothSnapshot) -> Result<(), StepError> {
        let expected = self.model.vertex_count();
        for got in [snapshot.positions.len(), snapshot.velocities.len()] {
            if got != expected {
                return Err(StepError::StateMismatch { expected, got });
            }
        }
        if snapshot.pins != self.model.pins() {
            return Err(StepError::PinsMismatch {
                expected: self.model.pins().len(),
                got: snapshot.pins.len(),
            });
        }
        let finite = |v: &[f32; 3]| v.iter().all(|c| c.is_finite());
        if !(snapshot.positions.iter().all(finite)
            && snapshot.velocities.iter().all(finite)
            && snapshot
                .pins_stepped
                .iter()
                .all(|(p, x)| (*p as usize) < expected && finite(x)))
        {
            return Err(StepError::InvalidSnapshot);
        }
        let vector = |v: &[f32; 3]| Vec3A::from_array(*v);
        self.state.positions = snapshot.positions.iter().map(vector).collect();
        self.state.velocities = snapshot.velocities.iter().map(vector).collect();
        self.pins_stepped = snapshot
            .pins_stepped
            .iter()
            .map(|(p, x)| (*p, vector(x)))
            .collect();
        self.guard_memory = GuardMemory {
            halvings: snapshot.halvings,
            calm_steps: snapshot.calm_steps,
            recovering: snapshot.recovering,
        };
        self.measured = None;
        self.initialized = true;
        self.placed_at = None;
        Ok(())
    }
}
