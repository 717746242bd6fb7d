//! Headless `App` tests of the real plugin (one test binary, so Bevy is
//! linked once).

mod assignment;
mod attach;
#[cfg(feature = "avian")]
mod avian;
// The cape example's scene (character, garments, run, body count), shared
// with `examples/cape.rs` and `headless --scene cape`.
#[path = "../../examples/character/mod.rs"]
#[allow(dead_code)]
mod cape_scene;
mod character;
mod colliders;
mod common;
#[cfg(feature = "picking")]
mod drag;
// The drape example's scene (two self-colliding sheets onto a ball, the
// exact check), shared with `examples/drape.rs` and `headless --scene drape`.
#[path = "../../examples/drape/mod.rs"]
#[allow(dead_code)]
mod drape_scene;
mod fuzz;
mod materials;
mod mesh_order;
mod meshes;
mod mistakes;
mod plugin;
mod save;
mod scenes;
mod self_collision;
mod tunnelling;
mod wind;
