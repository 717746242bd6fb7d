//! A cloth from a mesh asset that may still be loading (glTF).

use std::sync::Arc;

use bevy::asset::LoadState;
use bevy::prelude::*;

use super::Cloth;
use crate::model::{ClothBuildError, ClothBuilder};

/// How a loaded mesh becomes a cloth: the builder from the welded mesh
/// (`ClothBuilder::from_mesh`), to configure (mass, pins, springs).
type Configure = dyn Fn(&Mesh, ClothBuilder) -> Result<ClothBuilder, ClothBuildError> + Send + Sync;

/// Makes its entity a [`Cloth`] as soon as `mesh` is loaded: a glTF mesh
/// (`asset_server.load("cape.glb#Mesh0/Primitive0")`) can be given before
/// it is ready. The mesh is welded along its seams
/// ([`ClothBuilder::from_mesh`]) and configured by
/// [`with`](Self::with); then `Cloth` is inserted (placed at the entity's
/// transform) and this component removed. Put the method component on the
/// entity from the start; it waits for the cloth.
///
/// A mesh that cannot be a cloth (no positions or triangles, a bad pin) or
/// that fails to load is reported with a warning and this component
/// removed: no cloth, no panic. Needs `Assets<Mesh>` (Bevy's `AssetPlugin`
/// and mesh plugin, which `DefaultPlugins` has).
///
/// For the mesh write-back (`render::ClothRenderPlugin`), give the entity a
/// `Mesh3d` of its own copy of the mesh: the write-back deforms the asset.
///
/// ```
/// use bevy::prelude::*;
/// use bevy_cloth::prelude::*;
///
/// fn spawn(mut commands: Commands, server: Res<AssetServer>) {
///     let mesh: Handle<Mesh> = server.load("cape.glb#Mesh0/Primitive0");
///     commands.spawn((
///         ClothFromMesh::new(mesh).with(|mesh, builder| {
///             // Pin the vertices painted red.
///             let red = mesh_vertices_where(mesh, Mesh::ATTRIBUTE_COLOR, |c| c[0] > 0.5)?;
///             Ok(builder.with_total_mass(2.0).with_pins(red))
///         }),
///         ProjectiveSolver::default(),
///     ));
/// }
/// # bevy::ecs::system::assert_is_system(spawn);
/// ```
#[derive(Component, Clone)]
#[require(Transform)]
pub struct ClothFromMesh {
    /// The mesh to simulate.
    pub mesh: Handle<Mesh>,
    configure: Option<Arc<Configure>>,
}

impl std::fmt::Debug for ClothFromMesh {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ClothFromMesh")
            .field("mesh", &self.mesh)
            .field("configured", &self.configure.is_some())
            .finish()
    }
}

impl ClothFromMesh {
    /// A cloth of this mesh, with the builder's defaults (mass 1 per
    /// vertex, no pins).
    pub fn new(mesh: Handle<Mesh>) -> Self {
        Self {
            mesh,
            configure: None,
        }
    }

    /// Configures the builder once the mesh is loaded (it sees the mesh,
    /// to pick pins by an attribute: see
    /// [`mesh_vertices_where`](crate::model::mesh_vertices_where)).
    #[must_use]
    pub fn with(
        mut self,
        configure: impl Fn(&Mesh, ClothBuilder) -> Result<ClothBuilder, ClothBuildError>
        + Send
        + Sync
        + 'static,
    ) -> Self {
        self.configure = Some(Arc::new(configure));
        self
    }

    /// The cloth, from the loaded mesh.
    pub fn build(&self, mesh: &Mesh) -> Result<Cloth, ClothBuildError> {
        let builder = ClothBuilder::from_mesh(mesh)?;
        let builder = match &self.configure {
            Some(configure) => configure(mesh, builder)?,
            None => builder,
        };
        Cloth::build(builder)
    }
}

/// In `PreUpdate`: builds the cloths whose mesh is ready.
pub(crate) fn build_cloths_from_meshes(
    mut commands: Commands,
    pending: Query<(Entity, &ClothFromMesh)>,
    meshes: Option<Res<Assets<Mesh>>>,
    server: Option<Res<AssetServer>>,
    mut warned: Local<bool>,
) {
    let Some(meshes) = meshes else {
        if !*warned {
            warn!(
                "ClothFromMesh waits for Assets<Mesh>, which this app does not have: add Bevy's \
                 AssetPlugin and MeshPlugin (DefaultPlugins has both)"
            );
            *warned = true;
        }
        return;
    };
    for (entity, source) in &pending {
        if let Some(mesh) = meshes.get(&source.mesh) {
            let mut entity_commands = commands.entity(entity);
            entity_commands.remove::<ClothFromMesh>();
            match source.build(mesh) {
                Ok(cloth) => {
                    entity_commands.insert(cloth);
                }
                Err(error) => warn!("entity {entity}: its mesh cannot be a cloth: {error}"),
            }
        } else if let Some(LoadState::Failed(error)) =
            server.as_ref().and_then(|s| s.get_load_state(&source.mesh))
        {
            warn!("entity {entity}: its cloth mesh failed to load: {error}");
            commands.entity(entity).remove::<ClothFromMesh>();
        }
    }
}
