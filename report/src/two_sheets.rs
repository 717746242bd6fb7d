//! The contact map's two-cloth row (issue N: "two cloths, likewise"): two
//! cotton sheets dropped onto each other over a ball on the ground, stepped
//! through the plugin itself (an `App` of `MinimalPlugins` and
//! [`ClothPlugins`], one fixed step per update), so that what holds the
//! sheets apart is what a game runs: each sheet's step seeing the other's
//! vertices, the pass between cloths after the steps and its take-back of
//! edges already through. The single-sheet rows ([`crate::contact`]) call
//! the library's step directly; the pass between cloths lives in the
//! plugin's systems, so this row runs them.
//!
//! After every step the exact check counts the mesh edges of either sheet
//! through a triangle of the other ([`count_crossings`]) and through its own
//! ([`count_intersections`]); the row's cell is the most after any step, as
//! for the folded sheet. The plugin's not-converged flag counts too: a
//! sheet whose steps are mostly not converged "locks" (a stiff sheet under
//! too few iterations can hang in the air, apart and unstretched), and its
//! cell says so.

use bevy::app::App;
use bevy::math::{Quat, Vec3};
use bevy::prelude::{Entity, Fixed, MinimalPlugins, Time, Transform};
use bevy::time::TimeUpdateStrategy;
use std::panic::{AssertUnwindSafe, catch_unwind};

use bevy_cloth::collision::SelfCollision;
use bevy_cloth::collision::self_contact::{
    IntersectionCheck, count_crossings, count_intersections,
};
use bevy_cloth::methods::AnyMethod;
use bevy_cloth::model::{ClothBuilder, ClothMaterial};
use bevy_cloth::solver::max_stretch;
use bevy_cloth::{
    Cloth, ClothGuard, ClothPlugins, ClothStats, ClothStatus, PlaneCollider, SphereCollider,
};

use crate::contact::ContactRun;
use crate::scenarios::panicked;

/// Two `cols`² cotton sheets of 1 m, with self-collision at
/// [`SelfCollision::for_model`], dropped from 0.65 m and 0.9 m (the upper
/// turned by 20°) onto a 30 cm ball resting on the ground, for `seconds`
/// at 60 Hz: they land on each other over the ball, and their corners fold
/// onto the ground and onto each other.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TwoSheets {
    /// Vertices along each side of each sheet.
    pub cols: usize,
    /// Seconds simulated.
    pub seconds: f32,
}

impl TwoSheets {
    /// The map's row name.
    pub fn name(&self) -> String {
        format!(
            "two {}² sheets on each other over a ball, {} s",
            self.cols, self.seconds
        )
    }

    /// Runs the scene with `method` on both sheets: the steps completed,
    /// the guard's stop (the first of either sheet), the most edges through
    /// (either sheet's through the other's triangles and through its own)
    /// after any step and the largest stretch of either.
    pub fn run(&self, method: &AnyMethod) -> ContactRun {
        let mut out = ContactRun::default();
        let result = catch_unwind(AssertUnwindSafe(|| self.run_into(method, &mut out)));
        out.failed = match result {
            Err(panic) => Some(panicked(&*panic)),
            Ok(()) => out.failed.take(),
        };
        out
    }

    /// The scene's app with `method` on both sheets, their self-collision
    /// on or off, the guard's pause policy (as in the map's other rows; a
    /// game's default retries a failed step in halved steps), one fixed
    /// step per update from the second update on; and the two sheets.
    pub fn app(&self, method: &AnyMethod, self_collision: bool) -> (App, [Entity; 2]) {
        let mut app = App::new();
        app.add_plugins((MinimalPlugins, ClothPlugins::default()))
            .insert_resource(Time::<Fixed>::from_seconds(1.0 / 60.0))
            .insert_resource(TimeUpdateStrategy::FixedTimesteps(1));
        app.finish();
        app.cleanup();
        let world = app.world_mut();
        world.spawn((PlaneCollider::new(0.5), Transform::default()));
        world.spawn((
            SphereCollider::new(0.3).with_friction(0.5),
            Transform::from_xyz(0.0, 0.3, 0.0),
        ));
        let sheets = [(0.65, 0.0), (0.9, 20f32.to_radians())].map(|(height, turn)| {
            let model = ClothBuilder::grid(
                self.cols,
                self.cols,
                Vec3::new(-0.5, 0.0, -0.5),
                Vec3::new(-0.5, 0.0, 0.5),
                Vec3::new(0.5, 0.0, -0.5),
            )
            .build()
            .expect("a valid grid");
            let sc = SelfCollision::for_model(&model);
            let at =
                Transform::from_xyz(0.0, height, 0.0).with_rotation(Quat::from_rotation_y(turn));
            let cloth = (
                Cloth::new(model),
                ClothMaterial::COTTON,
                ClothGuard::pause(),
                at,
            );
            let mut entity = world.spawn(cloth);
            if self_collision {
                entity.insert(sc);
            }
            method.insert_now(&mut entity);
            entity.id()
        });
        (app, sheets)
    }

    fn run_into(&self, method: &AnyMethod, out: &mut ContactRun) {
        let (mut app, sheets) = self.app(method, true);
        let mut check = IntersectionCheck::default();
        let steps = (self.seconds * 60.0).round().max(1.0) as u64;
        // One fixed step per update, but the first (whose time delta is
        // zero) runs none.
        for _ in 0..steps + 2 {
            if out.steps == steps as usize {
                break;
            }
            app.update();
            let world = app.world();
            let stats = |e: Entity| world.get::<ClothStats>(e).expect("a cloth's stats");
            let done = stats(sheets[0]).steps.max(stats(sheets[1]).steps) as usize;
            if let Some(reason) = sheets.iter().find_map(|&e| match &stats(e).status {
                ClothStatus::Diverged(reason) => Some(*reason),
                _ => None,
            }) {
                out.caught = Some((out.steps, reason));
                return;
            }
            for &e in &sheets {
                if !matches!(stats(e).status, ClothStatus::Running) {
                    out.failed = Some(format!("not running: {:?}", stats(e).status));
                    return;
                }
            }
            if done == out.steps {
                continue;
            }
            out.steps = done;
            let cloth = |e: Entity| world.get::<Cloth>(e).expect("a cloth");
            let (a, b) = (cloth(sheets[0]), cloth(sheets[1]));
            let (xa, xb) = (&a.state().positions, &b.state().positions);
            if !(a.state().is_finite() && b.state().is_finite()) {
                out.failed = Some("non-finite state passed the guard".into());
                return;
            }
            let through = edges_through(a, b, &mut check);
            out.penetrations = out.penetrations.max(through);
            out.unconverged = sheets
                .iter()
                .map(|&e| stats(e).unconverged_steps as usize)
                .max()
                .unwrap_or(0);
            out.max_stretch = out
                .max_stretch
                .max(max_stretch(a.model(), xa))
                .max(max_stretch(b.model(), xb));
        }
    }
}

/// The exact check on two cloths: the mesh edges of either through a
/// triangle of the other, and through its own.
pub fn edges_through(a: &Cloth, b: &Cloth, check: &mut IntersectionCheck) -> usize {
    let (xa, xb) = (&a.state().positions, &b.state().positions);
    count_crossings((a.model(), xa), (b.model(), xb), check)
        + count_intersections(a.model(), xa, check)
        + count_intersections(b.model(), xb, check)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The row through the plugin: a tiny pair of sheets that meet within
    /// half a second, run twice to the same cell, and apart with the
    /// default method.
    #[test]
    fn two_small_sheets_land_on_each_other_apart_and_the_same_each_run() {
        let case = TwoSheets {
            cols: 10,
            seconds: 0.6,
        };
        let method = AnyMethod::default();
        let run = case.run(&method);
        assert_eq!(run.steps, 36, "{run:?}");
        assert!(run.failed.is_none() && run.caught.is_none(), "{run:?}");
        assert_eq!(run.penetrations, 0, "{run:?}");
        assert!(run.max_stretch > 0.0 && run.max_stretch < 0.1, "{run:?}");
        let again = case.run(&method);
        assert_eq!(run.cell(false), again.cell(false));
        assert_eq!(run.max_stretch.to_bits(), again.max_stretch.to_bits());
    }
}
