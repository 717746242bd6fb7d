//! Pins held by other entities: a cape's top edge on a character, a flag's
//! edge on its pole.

use bevy::ecs::lifecycle::HookContext;
use bevy::ecs::world::DeferredWorld;
use bevy::math::Affine3A;
use bevy::prelude::*;
use bevy::transform::helper::TransformHelper;

use super::{Cloth, ClothStats};

/// Vertices of this cloth held by other entities. Put it on the cloth's
/// entity; edit it at any time to attach, detach or re-attach (the change
/// takes effect at the next fixed step; a method that factorises its matrix
/// refactorises then).
///
/// Each [`Attachment`]'s vertices follow its `target`'s global transform as
/// if the cloth were the target's child placed by `offset`: vertex `i` is
/// held at `target · offset · rest[i]`, where `rest[i]` is its rest position
/// in the cloth's own space. They are pinned for every method while
/// attached; detached, they are free again (or follow the cloth's own
/// entity if the cloth was built with them pinned).
///
/// Mistakes are logged, never a panic: an attachment with a vertex out of
/// range is skipped with a warning; a vertex held by two attachments goes to
/// the first (warned once); an attachment whose target is despawned (or has
/// no transform) releases its vertices with a warning and is removed.
///
/// ```
/// use bevy::prelude::*;
/// use bevy_cloth::prelude::*;
///
/// fn spawn(mut commands: Commands) {
///     let pole = commands.spawn(Transform::from_xyz(0.0, 4.0, 0.0)).id();
///     let model = ClothBuilder::lab_grid(11).build().unwrap();
///     // The edge at x = 5 (in the cloth's rest space) held by the pole.
///     let edge = model.vertices_where(|p| p.x > 4.99);
///     commands.spawn((
///         Cloth::new(model),
///         ProjectiveSolver::default(),
///         ClothAttachments::new([Attachment::new(pole, edge)]),
///     ));
/// }
/// # bevy::ecs::system::assert_is_system(spawn);
/// ```
#[derive(Component, Reflect, Clone, Debug, Default, PartialEq)]
#[reflect(Component, Debug, PartialEq, Default)]
#[component(on_remove = release_all)]
pub struct ClothAttachments(pub Vec<Attachment>);

/// Removing [`ClothAttachments`] releases every held vertex at once (own
/// pins go back to the cloth's entity at the next step).
fn release_all(mut world: DeferredWorld, context: HookContext) {
    if let Some(mut cloth) = world.get_mut::<Cloth>(context.entity) {
        let own = cloth.own_pins.clone();
        if cloth.model.set_pins(own).is_ok() {
            cloth.attached.clear();
        }
    }
}

/// A set of a cloth's vertices held by one entity (see [`ClothAttachments`]).
#[derive(Reflect, Clone, Debug, PartialEq)]
#[reflect(Debug, PartialEq)]
pub struct Attachment {
    /// The entity holding the vertices.
    pub target: Entity,
    /// The held vertices (indices into the cloth's model).
    pub vertices: Vec<u32>,
    /// Places the cloth's rest space in the target's space.
    pub offset: Transform,
}

impl Attachment {
    /// `vertices` held by `target`, with no offset.
    pub fn new(target: Entity, vertices: impl IntoIterator<Item = u32>) -> Self {
        Self {
            target,
            vertices: vertices.into_iter().collect(),
            offset: Transform::IDENTITY,
        }
    }

    /// The same attachment with the cloth's rest space placed by `offset` in
    /// the target's space.
    #[must_use]
    pub fn with_offset(mut self, offset: Transform) -> Self {
        self.offset = offset;
        self
    }
}

impl ClothAttachments {
    /// These attachments.
    pub fn new(attachments: impl IntoIterator<Item = Attachment>) -> Self {
        Self(attachments.into_iter().collect())
    }

    /// Adds an attachment (the vertices it shares with an earlier one stay
    /// with the earlier one).
    pub fn attach(&mut self, attachment: Attachment) {
        self.0.push(attachment);
    }

    /// Releases every vertex `target` holds; returns whether it held any.
    pub fn detach(&mut self, target: Entity) -> bool {
        let before = self.0.len();
        self.0.retain(|a| a.target != target);
        self.0.len() != before
    }
}

/// What [`hold_attached`] warned about, and its scratch.
#[derive(Default)]
pub(crate) struct HoldMemory {
    warned: Vec<(Entity, Entity)>,
    held: Vec<bool>,
    /// (vertex, where it is held) of the cloth at hand.
    targets: Vec<(u32, Vec3A)>,
    gone: Vec<usize>,
    attached: Vec<u32>,
}

/// In `SyncIn`, after the cloths are placed and their own pins moved:
/// updates each cloth's pinned set from its attachments and moves the held
/// vertices to their targets (their velocity is the displacement over the
/// step; a vertex attached this step starts at rest).
pub(crate) fn hold_attached(
    time: Res<Time>,
    helper: TransformHelper,
    mut cloths: Query<(Entity, &mut Cloth, &mut ClothAttachments)>,
    mut memory: Local<HoldMemory>,
) {
    let dt = time.delta_secs();
    let HoldMemory {
        warned,
        held,
        targets,
        gone,
        attached,
    } = &mut *memory;
    for (entity, mut cloth, mut attachments) in &mut cloths {
        let cloth = &mut *cloth;
        if !cloth.initialized {
            continue;
        }
        let n = cloth.model.vertex_count();
        held.clear();
        held.resize(n, false);
        // (vertex, where it is held) for every valid attachment, first wins.
        targets.clear();
        gone.clear();
        {
            for (k, a) in attachments.0.iter().enumerate() {
                let Ok(global) = helper.compute_global_transform(a.target) else {
                    warn!(
                        "cloth {entity}: its attachment to {} is released, since that entity is \
                         gone (or has no transform)",
                        a.target
                    );
                    gone.push(k);
                    continue;
                };
                if let Some(&bad) = a.vertices.iter().find(|&&v| v as usize >= n) {
                    if !warned.contains(&(entity, a.target)) {
                        warn!(
                            "cloth {entity}: its attachment to {} is skipped: vertex {bad} is out \
                             of range for {n} vertices",
                            a.target
                        );
                        warned.push((entity, a.target));
                    }
                    continue;
                }
                let place: Affine3A = global.affine() * a.offset.compute_affine();
                if !place.is_finite() {
                    continue;
                }
                let rest = cloth.model.topology().rest_positions();
                for &v in &a.vertices {
                    if std::mem::replace(&mut held[v as usize], true) {
                        if !warned.contains(&(entity, a.target)) {
                            warn!(
                                "cloth {entity}: vertex {v} is held by an earlier attachment too; \
                                 it stays with the first, not {}",
                                a.target
                            );
                            warned.push((entity, a.target));
                        }
                        continue;
                    }
                    targets.push((v, place.transform_point3a(rest[v as usize].into())));
                }
            }
            // Removing the dead ones is what the warning said.
            for &k in gone.iter().rev() {
                attachments.0.remove(k);
            }
        }
        attached.clear();
        attached.extend(targets.iter().map(|&(v, _)| v));
        attached.sort_unstable();
        if *attached != cloth.attached {
            let mut pins: Vec<u32> = cloth
                .own_pins
                .iter()
                .copied()
                .filter(|&p| attached.binary_search(&p).is_err())
                .chain(attached.iter().copied())
                .collect();
            pins.sort_unstable();
            if let Err(error) = cloth.model.set_pins(pins) {
                // Unreachable: the vertices were checked above.
                warn!("cloth {entity}: attachments not applied: {error}");
                continue;
            }
            for &(v, _) in targets.iter() {
                if cloth.attached.binary_search(&v).is_err() {
                    cloth.state.velocities[v as usize] = Vec3A::ZERO;
                    cloth.state.positions[v as usize] = Vec3A::NAN;
                }
            }
            // Own pins released by an attachment go back to the cloth's own
            // entity now (its pinning ran before this, while they were held).
            let own = helper.compute_global_transform(entity).map(|g| g.affine());
            for &v in &cloth.attached {
                if attached.binary_search(&v).is_err()
                    && cloth.own_pins.contains(&v)
                    && let Ok(own) = own
                {
                    let rest = cloth.model.topology().rest_positions()[v as usize];
                    cloth.state.positions[v as usize] = own.transform_point3a(rest.into());
                    cloth.state.velocities[v as usize] = Vec3A::ZERO;
                }
            }
            cloth.attached.clone_from(attached);
        }
        for &(v, target) in targets.iter() {
            let v = v as usize;
            let old = cloth.state.positions[v];
            // A vertex attached this step (marked NaN above) starts at rest.
            if dt > 0.0 && old.is_finite() {
                cloth.state.velocities[v] = (target - old) / dt;
            }
            cloth.state.positions[v] = target;
        }
    }
}

/// In `PostUpdate`, after transform propagation: held vertices of running
/// cloths move to where their targets are now (positions only), so a
/// target moved in `Update` is followed in the same frame. Like the
/// fixed-step side, it computes the targets' global transforms from the
/// `Transform` hierarchy (an app without transform propagation works too).
pub(crate) fn follow_attached(
    mut cloths: Query<(&mut Cloth, &ClothStats, &ClothAttachments)>,
    helper: TransformHelper,
) {
    for (mut cloth, stats, attachments) in &mut cloths {
        if !cloth.initialized || !stats.is_running() || cloth.attached.is_empty() {
            continue;
        }
        let cloth = &mut *cloth;
        // Last to first, so the first attachment holding a vertex wins.
        for a in attachments.0.iter().rev() {
            let Ok(global) = helper.compute_global_transform(a.target) else {
                continue;
            };
            let place = global.affine() * a.offset.compute_affine();
            if !place.is_finite() {
                continue;
            }
            let rest = cloth.model.topology().rest_positions();
            for &v in &a.vertices {
                if cloth.attached.binary_search(&v).is_ok() {
                    cloth.state.positions[v as usize] =
                        place.transform_point3a(rest[v as usize].into());
                }
            }
        }
    }
}
