//! The character-cloth component and plugin: a cloth skinned to joint
//! entities by linear blend skinning, held to its skinned pose.

use bevy::ecs::schedule::common_conditions::any_with_component;
use bevy::math::{Affine3A, Mat3A, Mat4, Vec3A};
use bevy::mesh::skinning::{SkinnedMesh, SkinnedMeshInverseBindposes};
use bevy::mesh::{Mesh, MeshVertexAttribute, VertexAttributeValues, VertexFormat};
use bevy::prelude::*;
use bevy::transform::helper::TransformHelper;

use super::inertia::{ClothInertia, carry_with_anchor};
use super::{SkinConstraints, SkinError, SkinPose, SkinTethers, apply_skin};
use crate::ecs::{
    Cloth, ClothCorePlugin, ClothSchedule, ClothStats, ClothSystems, guard_and_measure,
    place_and_pin, scheduled_plugin,
};
use crate::model::ClothModel;

/// A cloth held near an animated shape (see the [module docs](super)): its
/// constraints, its skinned pose this step, and optionally the linear
/// blend skinning that makes the pose from joint entities each step.
///
/// With [`skinning`](Self::skinning), [`CharacterClothPlugin`] computes
/// [`pose`](Self::pose) every step from the joints' global transforms
/// (before the step), moves the cloth's pinned vertices to their skinned
/// positions (so a collar follows the body, and `stiff` moves it smoothly
/// through its substeps), and after the step applies the constraints
/// (`stiff` applies them in every substep too, the skin moved from the last
/// step's pose to this one's through them). Without it, the game writes
/// `pose` itself (from its own animation), and the pins follow that. Either
/// way the pins are on the skin, not where the entity's transform would
/// put them. If a joint entity goes, the skin and the vertices pinned on it
/// are released with a warning (the cloth falls free); insert a new
/// `ClothSkin` to skin it again.
#[derive(Component, Clone, Debug)]
pub struct ClothSkin {
    /// Max distance, backstop, anim drive and tethers.
    pub constraints: SkinConstraints,
    /// The skinned pose of this step, one entry per cloth vertex.
    pub pose: SkinPose,
    /// The skinning that computes `pose`, if any.
    pub skinning: Option<Skinning>,
    tethers: SkinTethers,
    /// The pose's positions at the last step's end (where the skin moves
    /// from through `stiff`'s substeps).
    pub(crate) previous: Vec<bevy::math::Vec3A>,
    /// Whether a joint went and the skin was released.
    released: bool,
}

impl ClothSkin {
    /// Constraints to a pose the game sets.
    pub fn new(constraints: SkinConstraints, pose: SkinPose) -> Self {
        Self {
            constraints,
            pose,
            skinning: None,
            tethers: SkinTethers::default(),
            previous: Vec::new(),
            released: false,
        }
    }

    /// Constraints to the pose `skinning` computes each step.
    pub fn skinned(constraints: SkinConstraints, skinning: Skinning) -> Self {
        Self {
            constraints,
            pose: SkinPose::default(),
            skinning: Some(skinning),
            tethers: SkinTethers::default(),
            previous: Vec::new(),
            released: false,
        }
    }
}

/// Linear blend skinning of a cloth's vertices, as Bevy's renderer skins a
/// [`SkinnedMesh`]: a vertex's skinned position is
/// `Σ wₖ · (Jₖ · Bₖ⁻¹) · p`, with `p` its bind-pose position, `Jₖ` the
/// global transform of its joint `k` and `Bₖ⁻¹` that joint's inverse bind
/// pose (its normal by the inverse transpose of that blend, normalised, as
/// Bevy's vertex shader moves it), computed on the CPU for the
/// cloth's vertices only.
#[derive(Clone, Debug, PartialEq)]
pub struct Skinning {
    /// The joint entities.
    pub joints: Vec<Entity>,
    /// Each joint's inverse bind pose.
    pub inverse_bindposes: Vec<Affine3A>,
    /// Per cloth vertex: up to four (joint, weight) influences.
    pub influences: Vec<[(u16, f32); 4]>,
    /// Per cloth vertex: its bind-pose position and normal.
    pub bind: Vec<(Vec3A, Vec3A)>,
    joint_matrices: Vec<Affine3A>,
}

/// A mesh's painted max distance per vertex (`Float32`, metres; see
/// [`SkinConstraints::with_painted`]). A glTF file's own attribute (a name
/// starting with `_`, as a DCC tool exports painted weights) maps onto it
/// with Bevy's `GltfPlugin::add_custom_vertex_attribute("_CLOTH_MAX_DISTANCE",
/// ATTRIBUTE_CLOTH_MAX_DISTANCE)`.
pub const ATTRIBUTE_CLOTH_MAX_DISTANCE: MeshVertexAttribute =
    MeshVertexAttribute::new("Cloth_MaxDistance", 0x0C10_7E5D_0001, VertexFormat::Float32);

/// A mesh's painted backstop distance per vertex (`Float32`, metres; see
/// [`SkinConstraints::with_painted`]).
pub const ATTRIBUTE_CLOTH_BACKSTOP: MeshVertexAttribute =
    MeshVertexAttribute::new("Cloth_Backstop", 0x0C10_7E5D_0002, VertexFormat::Float32);

impl SkinConstraints {
    /// These constraints with each cloth vertex's max distance and backstop
    /// distance painted on `mesh`, the mesh `model` was built from
    /// ([`ClothBuilder::from_mesh`](crate::model::ClothBuilder::from_mesh),
    /// welded or not): the [`ATTRIBUTE_CLOTH_MAX_DISTANCE`] and
    /// [`ATTRIBUTE_CLOTH_BACKSTOP`] attributes, where present (an absent
    /// one leaves its list as it is). Each cloth vertex takes the value of
    /// the first mesh vertex that became it, as [`Skinning::from_mesh`]
    /// takes its joints. A value that is NaN or negative is
    /// [`SkinError::Distance`]; an attribute of another format or length,
    /// or one that does not cover every cloth vertex, [`SkinError::Mesh`].
    pub fn with_painted(mut self, mesh: &Mesh, model: &ClothModel) -> Result<Self, SkinError> {
        let n = model.vertex_count();
        for (attribute, list) in [
            (ATTRIBUTE_CLOTH_MAX_DISTANCE, &mut self.max_distance),
            (ATTRIBUTE_CLOTH_BACKSTOP, &mut self.backstop_distance),
        ] {
            let Some(values) = mesh.try_attribute_option(attribute).ok().flatten() else {
                continue;
            };
            let VertexAttributeValues::Float32(values) = values else {
                return Err(SkinError::Mesh);
            };
            if values.iter().any(|d| d.is_nan() || *d < 0.0) {
                return Err(SkinError::Distance);
            }
            let mut painted = vec![None; n];
            for (j, &d) in values.iter().enumerate() {
                let c = match model.welded_from() {
                    Some(map) => map.get(j).map(|&c| c as usize),
                    None => Some(j),
                };
                if let Some(slot) = c.and_then(|c| painted.get_mut(c))
                    && slot.is_none()
                {
                    *slot = Some(d);
                }
            }
            if painted.contains(&None) || list.len() != n {
                return Err(SkinError::Mesh);
            }
            *list = painted.into_iter().flatten().collect();
        }
        Ok(self)
    }
}

impl Skinning {
    /// The skinning of a cloth built from `mesh` ([`ClothBuilder::from_mesh`](crate::model::ClothBuilder::from_mesh),
    /// welded or not): each cloth vertex takes the joints, weights,
    /// position and normal of the first mesh vertex that became it. The
    /// mesh needs positions, normals, joint indices (`Uint16x4`) and joint
    /// weights (`Float32x4`); a joint index past `skinned.joints`, a weight
    /// that is negative or NaN, or a mesh that does not match the cloth is a
    /// typed error.
    pub fn from_mesh(
        mesh: &Mesh,
        skinned: &SkinnedMesh,
        inverse_bindposes: &SkinnedMeshInverseBindposes,
        model: &ClothModel,
    ) -> Result<Self, SkinError> {
        let attribute = |a| mesh.try_attribute_option(a).ok().flatten();
        let (
            Some(VertexAttributeValues::Float32x3(positions)),
            Some(VertexAttributeValues::Float32x3(normals)),
            Some(VertexAttributeValues::Uint16x4(joints)),
            Some(VertexAttributeValues::Float32x4(weights)),
        ) = (
            attribute(Mesh::ATTRIBUTE_POSITION),
            attribute(Mesh::ATTRIBUTE_NORMAL),
            attribute(Mesh::ATTRIBUTE_JOINT_INDEX),
            attribute(Mesh::ATTRIBUTE_JOINT_WEIGHT),
        )
        else {
            return Err(SkinError::Mesh);
        };
        let n = model.vertex_count();
        let mut influences = vec![[(0u16, 0.0f32); 4]; n];
        let mut bind = vec![(Vec3A::ZERO, Vec3A::Z); n];
        let mut seen = vec![false; n];
        let count = positions.len();
        if [normals.len(), joints.len(), weights.len()]
            .iter()
            .any(|&l| l != count)
        {
            return Err(SkinError::Mesh);
        }
        for j in 0..count {
            let c = match model.welded_from() {
                Some(map) => map.get(j).map(|&c| c as usize),
                None => (j < n).then_some(j),
            };
            if weights[j].iter().any(|w| w.is_nan() || *w < 0.0) {
                return Err(SkinError::Weight);
            }
            let Some(c) = c.filter(|&c| c < n && !seen[c]) else {
                continue;
            };
            seen[c] = true;
            if joints[j]
                .iter()
                .zip(weights[j])
                .any(|(&k, w)| w != 0.0 && usize::from(k) >= skinned.joints.len())
            {
                return Err(SkinError::Joint);
            }
            influences[c] = std::array::from_fn(|k| (joints[j][k], weights[j][k]));
            bind[c] = (
                Vec3A::from_array(positions[j]),
                Vec3A::from_array(normals[j]).normalize_or_zero(),
            );
        }
        if seen.contains(&false) {
            return Err(SkinError::Mesh);
        }
        if inverse_bindposes.len() < skinned.joints.len() {
            return Err(SkinError::Joint);
        }
        Ok(Self {
            joints: skinned.joints.clone(),
            inverse_bindposes: inverse_bindposes
                .iter()
                .map(|m: &Mat4| Affine3A::from_mat4(*m))
                .collect(),
            influences,
            bind,
            joint_matrices: Vec::new(),
        })
    }

    /// Skins every vertex into `pose` with the joints' global transforms
    /// from `joint_global` (`None` for a joint without one: the skinning is
    /// skipped and `false` returned).
    pub fn pose(
        &mut self,
        joint_global: impl Fn(Entity) -> Option<Affine3A>,
        pose: &mut SkinPose,
    ) -> bool {
        self.joint_matrices.clear();
        for (&joint, inverse) in self.joints.iter().zip(&self.inverse_bindposes) {
            let Some(global) = joint_global(joint) else {
                return false;
            };
            self.joint_matrices.push(global * *inverse);
        }
        let n = self.bind.len();
        pose.positions.resize(n, Vec3A::ZERO);
        pose.normals.resize(n, Vec3A::Z);
        let vertices = self.influences.iter().zip(&self.bind);
        let out = pose.positions.iter_mut().zip(pose.normals.iter_mut());
        for ((influences, &(p, normal)), (x, nrm)) in vertices.zip(out) {
            // As Bevy's vertex shader does: blend the joint matrices, move
            // the position by the blend and the normal by its inverse
            // transpose (right under non-uniform scale, where moving the
            // normal by the blend is not).
            let (mut m, mut t) = (Mat3A::ZERO, Vec3A::ZERO);
            for &(k, w) in influences {
                if w != 0.0 {
                    let joint = &self.joint_matrices[usize::from(k)];
                    m += joint.matrix3 * w;
                    t += joint.translation * w;
                }
            }
            *x = m * p + t;
            let det = m.determinant();
            *nrm = if det != 0.0 && det.is_finite() {
                (m.inverse().transpose() * normal).normalize_or(normal)
            } else {
                normal
            };
        }
        true
    }
}

scheduled_plugin! {
    /// Character cloth ([`ClothSkin`], [`ClothInertia`]): before the step,
    /// skins the cloths that have a [`Skinning`] and moves their pins to
    /// their skinned positions (in [`ClothSystems::SyncIn`], after the
    /// core's pins), then carries each cloth with a [`ClothInertia`] by its
    /// share of its anchor's motion (or with a teleported anchor); after
    /// it and the colliders (first in [`ClothSystems::SyncOut`], before the
    /// guard's second check), holds every cloth with a `ClothSkin` to its
    /// pose (max distance, backstop, anim drive), for every method.
    CharacterClothPlugin
}

impl Plugin for CharacterClothPlugin {
    fn build(&self, app: &mut App) {
        ClothCorePlugin::new_interned(self.schedule).add_once(app);
        app.add_systems(
            ClothSchedule,
            (
                skin_cloths
                    .in_set(ClothSystems::SyncIn)
                    .after(place_and_pin),
                // After every collider's projection (the Collide set), before
                // the guard's second check.
                hold_to_skin
                    .in_set(ClothSystems::SyncOut)
                    .before(guard_and_measure),
            )
                .run_if(any_with_component::<ClothSkin>),
        );
        app.add_systems(
            ClothSchedule,
            // Once the pins are where their entity or skin puts them.
            carry_with_anchor
                .in_set(ClothSystems::SyncIn)
                .after(place_and_pin)
                .after(skin_cloths)
                .run_if(any_with_component::<ClothInertia>),
        );
    }
}

/// Skins every cloth with a [`Skinning`], and moves the pins of every
/// cloth with a pose to their skinned positions, with the velocity of that
/// move. A cloth one of whose joints is gone (despawned, or without a
/// transform) has its skin and the vertices pinned on it released, with a
/// warning: it falls free, as a gone attachment's vertices do.
pub(super) fn skin_cloths(
    time: Res<Time>,
    helper: TransformHelper,
    mut cloths: Query<(Entity, &mut Cloth, &mut ClothSkin)>,
) {
    let dt = time.delta_secs();
    for (entity, mut cloth, mut skin) in &mut cloths {
        let cloth = &mut *cloth;
        let ClothSkin {
            pose,
            skinning,
            previous,
            released,
            ..
        } = &mut *skin;
        if let Some(skinned) = skinning {
            let global = |e| helper.compute_global_transform(e).ok().map(|g| g.affine());
            if !skinned.pose(global, pose) {
                warn!(
                    "cloth {entity}: a joint of its skin is gone (or has no transform); the \
                     skin and the vertices pinned on it are released"
                );
                *skinning = None;
                *released = true;
                pose.positions.clear();
                pose.normals.clear();
                previous.clear();
                cloth.own_pins.clear();
                let held = cloth.attached.clone();
                if let Err(error) = cloth.model.set_pins(held) {
                    // Unreachable: the attached vertices are the cloth's.
                    warn!("cloth {entity}: pins not released: {error}");
                }
                continue;
            }
        }
        if !cloth.initialized || pose.positions.len() != cloth.model.vertex_count() {
            continue;
        }
        for &p in cloth.model.pins() {
            let (p, x) = (p as usize, pose.positions[p as usize]);
            if x.is_finite() {
                if dt > 0.0 {
                    cloth.state.velocities[p] = (x - cloth.state.positions[p]) / dt;
                }
                cloth.state.positions[p] = x;
            }
        }
    }
}

/// Holds every running cloth with a [`ClothSkin`] to its pose after the
/// step; a skin that does not fit its cloth is skipped with a warning
/// (once per entity).
fn hold_to_skin(
    time: Res<Time>,
    mut cloths: Query<(Entity, &mut Cloth, &mut ClothSkin, &ClothStats)>,
    mut warned: Local<Vec<Entity>>,
) {
    let dt = time.delta_secs();
    for (entity, mut cloth, mut skin, stats) in &mut cloths {
        if !cloth.initialized || !stats.is_running() {
            continue;
        }
        let cloth = &mut *cloth;
        let skin = &mut *skin;
        // A skin released when its joint went: nothing to hold to.
        if skin.released {
            continue;
        }
        match skin
            .constraints
            .validate(cloth.model.vertex_count(), &skin.pose)
        {
            Ok(()) => {
                // The skin's limits are held as a collider's projection is,
                // and measured so (see `ProjectedConvergence`).
                cloth.convergence.before_projection(&cloth.state.positions);
                apply_skin(
                    &cloth.model,
                    &mut cloth.state,
                    &skin.pose,
                    &skin.constraints,
                    &mut skin.tethers,
                    dt,
                );
                // The state changed after the step's own check.
                cloth.measured = None;
                skin.previous.clone_from(&skin.pose.positions);
            }
            Err(error) if !warned.contains(&entity) => {
                warn!("cloth {entity} is not held to its skin: {error}");
                warned.push(entity);
            }
            Err(_) => {}
        }
    }
}
