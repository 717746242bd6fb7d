//! Headless `App` tests of the real plugin (one test binary, so Bevy is
//! linked once).

mod assignment;
mod common;
#[cfg(feature = "picking")]
mod drag;
mod plugin;
mod scenes;
