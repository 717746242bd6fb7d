//! Headless `App` tests of the real plugin (one test binary, so Bevy is
//! linked once).

mod assignment;
mod common;
#[cfg(feature = "render")]
mod drag;
mod fuzz;
mod plugin;
mod scenes;
mod stability;
