//! The contact cases (issue N): a cotton sheet folded onto itself and
//! dropped on the ground, and a ball thrown through a sheet at 30 m/s.
//! The exact implicit-Euler run cannot judge them (self-collision and a
//! moving collider act after its step too), so they are judged by what a
//! player would see: the exact intersection check
//! ([`count_intersections`]) after every step, whether the ball came out
//! on the far side of the cloth, and the largest stretch. The stability
//! map runs them with every method ([`run`]); the perf page times one step
//! of the folded sheet with and without self-collision ([`Stepper`]).
//!
//! A step here is the plugin's: the method's step under the guard (with
//! self-collision inside it for `stiff`, after it for the others), then the
//! colliders' swept projection ([`project_swept`]).

use std::panic::{AssertUnwindSafe, catch_unwind};

use bevy::math::{Affine3A, Vec3, Vec3A};

use bevy_cloth::collision::self_contact::{
    IntersectionCheck, SelfCollisionInput, SelfContacts, count_intersections, ray_meets,
};
use bevy_cloth::collision::{Capsule, Plane, SelfCollision, Shape, Sweep, project_swept};
use bevy_cloth::methods::{AnyMethod, AnyWorkspace};
use bevy_cloth::model::{ClothBuilder, ClothMaterial, ClothModel, ClothState};
use bevy_cloth::solver::guard::{
    DivergenceReason, GuardBounds, GuardError, GuardMemory, GuardPolicy, guarded_step,
};
use bevy_cloth::solver::{
    CONVERGENCE_TOLERANCE, ProjectedConvergence, StepInput, StepParams, max_stretch,
};

use crate::scenarios::ended;
use crate::two_sheets::TwoSheets;

/// The thrown ball's speed (m/s).
pub const BALL_SPEED: f32 = 30.0;

/// A cloth among colliders, one of which may be thrown.
#[derive(Clone, Debug)]
pub struct ContactCase {
    /// Short name (the map's row).
    pub name: String,
    /// The cloth (cotton).
    pub model: ClothModel,
    /// Its parameters (cotton's springs, 1/60 s steps).
    pub params: StepParams,
    /// Where it starts, at rest.
    pub start: ClothState,
    /// The colliders (projected after every step; inside `stiff`'s
    /// substeps too).
    pub solids: Vec<Shape>,
    /// A collider that moves at a constant velocity from the second step
    /// on: its index in `solids` and its velocity.
    pub thrown: Option<(usize, Vec3A)>,
    /// The cloth's self-collision (`None`: off).
    pub self_collision: Option<SelfCollision>,
    /// Steps to run.
    pub steps: usize,
}

/// A `cols`-wide cotton sheet of 1 m × 1 m folded into `layers` layers
/// (a zig-zag along `x`, each fold a half circle), 5 cm above a ground of
/// friction 0.5, with self-collision at [`SelfCollision::for_model`]:
/// after its fall the layers land on each other.
pub fn folded(cols: usize, layers: usize, seconds: f32) -> ContactCase {
    let model = ClothBuilder::grid(
        cols,
        cols,
        Vec3::ZERO,
        Vec3::new(0.0, 0.0, 1.0),
        Vec3::new(1.0, 0.0, 0.0),
    )
    .with_material(ClothMaterial::COTTON)
    .build()
    .expect("a valid grid");
    let sc = SelfCollision::for_model(&model);
    // Layers 1.3 thicknesses apart: apart at the start, close enough that
    // a layer that falls through the one below shows at once.
    let r = 0.65 * sc.thickness;
    let layers = layers.max(1);
    let arc = core::f32::consts::PI * r;
    let a = (1.0 - (layers - 1) as f32 * arc) / layers as f32;
    let (x0, h) = (-0.5 * a, 0.05);
    // Where the point `s` metres along the unfolded sheet's `x` lies.
    let place = |s: f32| -> (f32, f32) {
        let piece = a + arc;
        let j = ((s / piece).floor() as usize).min(layers - 1);
        let u = s - j as f32 * piece;
        let y = h + 2.0 * r * j as f32;
        let forward = j.is_multiple_of(2);
        if u <= a || j == layers - 1 {
            let u = u.min(a);
            (if forward { x0 + u } else { x0 + a - u }, y)
        } else {
            let theta = (u - a) / r;
            let dx = r * theta.sin();
            let y = y + r * (1.0 - theta.cos());
            (if forward { x0 + a + dx } else { x0 - dx }, y)
        }
    };
    let mut start = ClothState::at_rest(&model, &Affine3A::IDENTITY);
    for p in &mut start.positions {
        let (x, y) = place(p.x);
        *p = Vec3A::new(x, y, p.z);
    }
    ContactCase {
        name: format!("{cols}² folded in {layers}, on the ground"),
        params: cotton_params(&model),
        start,
        solids: vec![Shape::Plane(Plane {
            point: Vec3A::ZERO,
            normal: Vec3A::Y,
            friction: 0.5,
        })],
        thrown: None,
        self_collision: Some(sc),
        steps: (seconds * 60.0).round().max(1.0) as usize,
        model,
    }
}

/// A free `cols`² cotton sheet of 2 m × 2 m, level, and a ball of `radius`
/// below it thrown straight up at [`BALL_SPEED`] (half a metre a step),
/// slightly off its middle, from 0.4 m below it: its top passes the
/// sheet's level within its first moving step, and it goes on for seven
/// more.
pub fn ball(cols: usize, radius: f32) -> ContactCase {
    let model = ClothBuilder::grid(
        cols,
        cols,
        Vec3::new(-1.0, 0.0, -1.0),
        Vec3::new(1.0, 0.0, -1.0),
        Vec3::new(-1.0, 0.0, 1.0),
    )
    .with_material(ClothMaterial::COTTON)
    .build()
    .expect("a valid grid");
    let center = Vec3A::new(0.02, -0.4 - radius, 0.03);
    ContactCase {
        name: format!("{cols}², a {:.0} cm ball at 30 m/s", radius * 100.0),
        params: cotton_params(&model),
        start: ClothState::at_rest(&model, &Affine3A::IDENTITY),
        solids: vec![Shape::Capsule(Capsule {
            a: center,
            b: center,
            radius,
            friction: 0.5,
        })],
        thrown: Some((0, Vec3A::new(0.0, BALL_SPEED, 0.0))),
        self_collision: None,
        steps: 9,
        model,
    }
}

fn cotton_params(model: &ClothModel) -> StepParams {
    StepParams {
        dt: 1.0 / 60.0,
        stiffness: ClothMaterial::COTTON.spring_stiffness(model),
        ..StepParams::LAB
    }
}

impl ContactCase {
    /// This case without self-collision, named so.
    pub fn without_self_collision(mut self) -> Self {
        self.self_collision = None;
        self.name.push_str(", no self-collision");
        self
    }

    /// The same case with a thinner self-collision: `share` of the cloth's
    /// shortest rest edge (below
    /// [`FACES_BELOW`](bevy_cloth::collision::self_contact::FACES_BELOW), vertex pairs alone do not
    /// keep the surface from passing through itself, and the
    /// vertex–triangle pairs take over). The cloth starts where it did.
    pub fn thin(mut self, share: f32) -> Self {
        if let Some(sc) = &mut self.self_collision {
            sc.thickness *= share / 0.9;
            self.name.push_str(&format!(", {share} of the edges thick"));
        }
        self
    }
}

/// What one step of a [`ContactCase`] keeps from step to step.
///
/// [`Stepper::default`] only steps; [`Stepper::judging`] also judges each
/// step's convergence as the plugin does, which costs a copy of the
/// positions and, for some steps, a second error measurement (so the perf
/// page, which times the step alone, does not judge).
#[derive(Default)]
pub struct Stepper {
    judge: bool,
    ws: AnyWorkspace,
    self_contacts: SelfContacts,
    backup: ClothState,
    memory: GuardMemory,
    motion: Vec<Vec3A>,
    convergence: ProjectedConvergence,
}

impl Stepper {
    /// A stepper that also judges each step's convergence (the map's ⚑).
    pub fn judging() -> Self {
        Self {
            judge: true,
            ..Self::default()
        }
    }

    /// One step of `case` with `method`, the colliders at `solids` (moved
    /// by the step if one is thrown): the method under the guard (pause
    /// policy), self-collision after it unless the method handled it, the
    /// swept projection. Returns the guard's verdict and, for a step it
    /// let through by a [`Stepper::judging`], whether the step converged
    /// as the plugin judges it
    /// ([`ClothStats::converged`](bevy_cloth::ClothStats::converged): the
    /// method's own relative error within [`CONVERGENCE_TOLERANCE`], or,
    /// when the projection moved the cloth, measured again without what
    /// the projection undid: [`ProjectedConvergence`]); `None` if not
    /// judging.
    pub fn step(
        &mut self,
        case: &ContactCase,
        method: &AnyMethod,
        state: &mut ClothState,
        solids: &mut [Shape],
        moving: bool,
    ) -> Result<Option<bool>, GuardError> {
        let model = &case.model;
        let dt = case.params.dt as f32;
        let mut params = case.params;
        self.motion.clear();
        self.motion.resize(solids.len(), Vec3A::ZERO);
        if let (true, Some((k, velocity))) = (moving, case.thrown)
            && let Some(solid) = solids.get_mut(k)
        {
            *solid = solid.translated(velocity * dt);
            self.motion[k] = velocity * dt;
            params.collider_speed = velocity.length();
        }
        let bounds = GuardBounds::default().for_method(method.uses_stiffness());
        let sc = case.self_collision.map(SelfCollisionInput::alone);
        let Self {
            judge,
            ws,
            self_contacts,
            backup,
            memory,
            motion,
            convergence,
        } = self;
        let solids = &*solids;
        let done = guarded_step(
            &bounds,
            GuardPolicy::Pause,
            memory,
            model,
            state,
            backup,
            &params,
            |s, p| {
                let input = StepInput {
                    model,
                    params: p,
                    spheres: &[],
                    contacts: solids,
                    contact_motion: motion,
                    skin: None,
                    self_collision: sc,
                };
                method.step_with(input, s, ws)
            },
        )?;
        if let Some(sc) = sc
            && done.report.self_contacts.is_none()
        {
            self_contacts.resolve_after_step(model, state, backup, &params, sc);
        }
        if *judge {
            let own = done.report.relative_error;
            convergence.stepped(own, done.substeps == 1, CONVERGENCE_TOLERANCE);
            convergence.before_projection(&state.positions);
        }
        let sweep = Sweep {
            motion,
            start: &backup.positions,
            share: done.last_substep().unwrap_or(1.0),
            edges: false,
        };
        project_swept(model, state, solids, sweep, 0.0, dt);
        let judged = convergence.settle(model, backup, &state.positions, &params);
        Ok(judged.map(|e| e.is_none_or(|e| e <= CONVERGENCE_TOLERANCE)))
    }
}

/// The end of one run of a [`ContactCase`].
#[derive(Clone, Debug, Default)]
pub struct ContactRun {
    /// Steps completed.
    pub steps: usize,
    /// The guard's stop: the step at which it happened and why.
    pub caught: Option<(usize, DivergenceReason)>,
    /// Why the run failed (a panic, or valid input refused).
    pub failed: Option<String>,
    /// The most mesh edges through the cloth's own triangles after any
    /// step (the exact check).
    pub penetrations: usize,
    /// The first step after which the cloth was no longer ahead of the
    /// thrown ball (no triangle met by a ray from the ball's centre along
    /// its motion): the ball passed.
    pub passed: Option<usize>,
    /// The most vertices inside the thrown ball after any step.
    pub inside: usize,
    /// The largest spring stretch after any step.
    pub max_stretch: f32,
    /// Steps flagged not converged: for the runs through the plugin
    /// ([`TwoSheets`]) its
    /// [`ClothStats::unconverged_steps`](bevy_cloth::ClothStats::unconverged_steps),
    /// the most of either cloth; for the others, [`Stepper::step`]'s
    /// verdict, the plugin's rule.
    pub unconverged: usize,
}

impl ContactRun {
    /// The map's cell: `✓` when the cloth stayed whole (largest stretch
    /// within [`TORN`]) and, for the folded sheet, never through itself;
    /// for the ball, in front of it with nothing inside; else what went
    /// wrong.
    pub fn cell(&self, thrown: bool) -> String {
        if let Some(why) = &self.failed {
            return format!("failed: {why}");
        }
        if let Some((step, reason)) = self.caught {
            return format!("caught @{step} {reason:?}");
        }
        let whole = self.max_stretch <= TORN;
        let stretch = format!("str {:.1} %", 100.0 * self.max_stretch);
        let (good, what) = if thrown {
            match self.passed {
                Some(step) => (false, format!("passed @{step}")),
                None if self.inside > 0 => (false, format!("{} inside", self.inside)),
                None => (true, "held".to_string()),
            }
        } else {
            (
                self.penetrations == 0,
                format!("{} through", self.penetrations),
            )
        };
        // A cloth whose steps are mostly not converged moves, but not as
        // implicit Euler would: a stiff sheet "locks" and can hang in the
        // air, apart and unstretched.
        let flagged = self.unconverged as f32 / self.steps.max(1) as f32;
        let (settled, flag) = match self.unconverged {
            0 => (true, String::new()),
            _ => (flagged <= FLAGGED, format!(" ⚑ {:.0} %", 100.0 * flagged)),
        };
        let mark = if good && whole && settled {
            "✓"
        } else {
            "✗"
        };
        format!("{mark} {what}; {stretch}{flag}")
    }
}

/// The largest stretch a cell may show and be `✓`: cotton stretched by
/// more than a tenth has torn.
pub const TORN: f32 = 0.1;

/// The largest share of its steps a run may have flagged not converged and
/// be `✓` (the map's tolerance for flagged steps).
pub const FLAGGED: f32 = 0.05;

/// Runs `method` through `case`: one step with everything still, then the
/// thrown collider (if any) moving, checking after every step.
pub fn run(case: &ContactCase, method: &AnyMethod) -> ContactRun {
    let mut out = ContactRun::default();
    let mut state = case.start.clone();
    let mut solids = case.solids.clone();
    let mut stepper = Stepper::judging();
    let mut check = IntersectionCheck::default();
    let result = catch_unwind(AssertUnwindSafe(|| {
        for n in 0..case.steps {
            match stepper.step(case, method, &mut state, &mut solids, n > 0) {
                Ok(converged) => out.unconverged += usize::from(converged == Some(false)),
                Err(GuardError::Diverged { reason, .. }) => {
                    out.caught = Some((n, reason));
                    return;
                }
                Err(GuardError::Refused(e)) => {
                    out.failed = Some(format!("refused: {e}"));
                    return;
                }
            }
            out.steps = n + 1;
            let x = &state.positions;
            out.max_stretch = out.max_stretch.max(max_stretch(&case.model, x));
            out.penetrations =
                out.penetrations
                    .max(count_intersections(&case.model, x, &mut check));
            if let Some((k, velocity)) = case.thrown
                && let Some(Shape::Capsule(ball)) = solids.get(k)
            {
                let center = ball.a;
                let inside = x
                    .iter()
                    .filter(|p| p.distance(center) < ball.radius - 1e-3)
                    .count();
                out.inside = out.inside.max(inside);
                let facing = velocity.normalize_or_zero();
                // Before the ball reaches the sheet's plane a ray always
                // meets it; after, only if the sheet is still ahead.
                if n > 0 && out.passed.is_none() && !ray_meets(&case.model, x, center, facing) {
                    out.passed = Some(n);
                }
            }
        }
    }));
    out.failed = ended(result, out.failed, &state);
    out
}

/// The sizes of the contact cases (this module's cases).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ContactSizes {
    /// Side of the folded sheet.
    pub folded: usize,
    /// Seconds it runs.
    pub seconds: f32,
    /// Side of the sheet the ball is thrown through.
    pub ball: usize,
    /// Side and seconds of the long fold (issue N's target: a 64² sheet in
    /// four layers, 10 s, no edge through).
    pub long: (usize, f32),
    /// Two sheets dropped on each other, through the plugin (issue N's
    /// "two cloths, likewise"; the committed map's are 32², as the drape
    /// scene's: at 64² the exact method alone takes 40 minutes of it).
    pub two: TwoSheets,
}

impl ContactSizes {
    /// The committed map's: a 32² sheet folded in four for 3 s, the ball
    /// through a 64² sheet, a 64² sheet folded in four for 10 s (issue
    /// N's) and two 32² sheets for 10 s.
    pub const FULL: Self = Self {
        folded: 32,
        seconds: 3.0,
        ball: 64,
        long: (64, 10.0),
        two: TwoSheets {
            cols: 32,
            seconds: 10.0,
        },
    };
    /// The tiny map's.
    pub const TINY: Self = Self {
        folded: 10,
        seconds: 0.1,
        ball: 8,
        long: (8, 0.1),
        two: TwoSheets {
            cols: 8,
            seconds: 0.1,
        },
    };

    /// The cases the library's step runs: the folded sheet with and
    /// without self-collision, the long fold, and balls of 25 and 10 cm
    /// (the two sheets, through the plugin, are [`two`](Self::two)).
    pub fn cases(&self) -> Vec<ContactCase> {
        let (side, seconds) = self.long;
        let mut long = folded(side, 4, seconds);
        let folded = folded(self.folded, 4, self.seconds);
        long.name = format!("{}, {seconds} s", long.name);
        vec![
            folded.clone(),
            folded.clone().without_self_collision(),
            folded.thin(0.3),
            long,
            ball(self.ball, 0.25),
            ball(self.ball, 0.1),
        ]
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use bevy_cloth::XpbdSolver;

    #[test]
    fn the_folded_sheet_starts_apart_with_its_rest_lengths_nearly_kept() {
        let case = folded(16, 4, 1.0);
        let mut check = IntersectionCheck::default();
        assert_eq!(
            count_intersections(&case.model, &case.start.positions, &mut check),
            0
        );
        // The folds' chords are shorter than their arcs: compressed, never
        // stretched.
        assert!(max_stretch(&case.model, &case.start.positions) < 1e-3);
        let top = case.start.positions.iter().map(|p| p.y).fold(0.0, f32::max);
        let thickness = case.self_collision.unwrap().thickness;
        assert!(top > 0.05 + 3.0 * thickness, "four layers: top at {top}");
    }

    #[test]
    fn stiff_keeps_the_folded_sheet_from_passing_through_itself_and_not_without() {
        let stiff = AnyMethod::Xpbd(XpbdSolver::STIFF);
        let with = run(&folded(16, 4, 1.0), &stiff);
        assert_eq!((with.caught, with.failed.clone()), (None, None));
        assert_eq!(with.penetrations, 0, "{with:?}");
        assert!(with.cell(false).starts_with('✓'));
        let without = run(&folded(16, 4, 1.0).without_self_collision(), &stiff);
        assert!(without.penetrations > 0, "{without:?}");
        assert!(without.cell(false).starts_with('✗'));
    }

    /// The single-sheet rows flag steps as the plugin does: a method with
    /// no relative error of its own (`stiff`) never, Jacobi's fixed
    /// iterations on cotton's stiff springs in most steps, and its cell
    /// says so.
    #[test]
    fn the_folded_sheet_flags_the_steps_the_plugin_would() {
        let case = folded(16, 4, 0.5);
        let stiff = run(&case, &AnyMethod::Xpbd(XpbdSolver::STIFF));
        assert_eq!(stiff.unconverged, 0, "{stiff:?}");
        let jacobi = bevy_cloth::methods::preset("jacobi").unwrap().method;
        let flagged = run(&case, &jacobi);
        assert_eq!((flagged.caught, flagged.failed.clone()), (None, None));
        assert!(2 * flagged.unconverged > flagged.steps, "{flagged:?}");
        let cell = flagged.cell(false);
        assert!(cell.starts_with('✗') && cell.contains('⚑'), "{cell}");
    }

    /// Self-collision on a cloth large enough for the parallel kernels
    /// (Chebyshev's and `pd`'s spring and vertex passes in chunks on the
    /// compute pool's threads; the pair search and passes are serial, and
    /// so is `stiff`'s loop, for which this is a run-after-run check): the
    /// same bits with and without the pool, with the pairs after the step
    /// (Chebyshev), in the objective (`pd`) and in the substeps (`stiff`).
    #[test]
    fn self_collision_gives_the_same_bits_on_one_thread_and_two() {
        use bevy::tasks::{ComputeTaskPool, TaskPoolBuilder};
        let pool = ComputeTaskPool::get_or_init(|| TaskPoolBuilder::new().num_threads(2).build());
        assert!(pool.thread_num() > 1);
        // Until the sheet has landed on the ground (5 cm down).
        const STEPS: usize = 8;
        let case = folded(185, 4, 0.1);
        assert!(case.model.vertex_count() >= bevy_cloth::solver::PARALLEL_MIN);
        for name in ["chebyshev", "pd", "stiff"] {
            let method = bevy_cloth::methods::preset(name).unwrap().method;
            let bits = |parallel: bool| {
                let mut case = case.clone();
                case.params.parallel = parallel;
                let mut state = case.start.clone();
                let mut solids = case.solids.clone();
                let mut stepper = Stepper::default();
                for _ in 0..STEPS {
                    stepper
                        .step(&case, &method, &mut state, &mut solids, false)
                        .unwrap();
                }
                (bits_of(&state), stepper.self_contacts.pair_count())
            };
            let (serial, pairs) = bits(false);
            assert_ne!(serial, bits_of(&case.start), "{name}: the sheet moved");
            // The pairs after the step (`stiff` holds them in its substeps).
            assert!(name == "stiff" || pairs > 0, "{name}: no pairs");
            assert!(
                (serial, pairs) == bits(true),
                "{name}: the pool changed the bits"
            );
        }
    }

    /// The bits of a state's positions and velocities.
    fn bits_of(state: &ClothState) -> Vec<u32> {
        state
            .positions
            .iter()
            .chain(&state.velocities)
            .flat_map(|p| p.to_array().map(f32::to_bits))
            .collect()
    }

    /// Judging is looked at, not done to the cloth: a stepper that judges
    /// and one that does not take the same steps, and only the first
    /// answers.
    #[test]
    fn judging_a_step_leaves_the_step_as_it_was() {
        let case = folded(12, 4, 0.5);
        let jacobi = bevy_cloth::methods::preset("jacobi").unwrap().method;
        let [(judged, judged_positions), (bare, bare_positions)] =
            [Stepper::judging(), Stepper::default()].map(|mut stepper| {
                let mut state = case.start.clone();
                let mut solids = case.solids.clone();
                let verdicts: Vec<_> = (0..10)
                    .map(|_| stepper.step(&case, &jacobi, &mut state, &mut solids, false))
                    .map(|done| done.unwrap())
                    .collect();
                (verdicts, state.positions)
            });
        assert!(bare.iter().all(Option::is_none), "{bare:?}");
        assert!(judged.iter().all(Option::is_some), "{judged:?}");
        assert!(judged.contains(&Some(false)), "{judged:?}");
        assert_eq!(judged_positions, bare_positions);
    }

    #[test]
    fn pbd_keeps_the_folded_sheet_from_passing_through_itself_within_its_iterations() {
        // Resolved only after its step, the pairs fought the next step's
        // strain limiting: 22 edges through and 45 % stretch here.
        let pbd = bevy_cloth::methods::preset("pbd").unwrap().method;
        let with = run(&folded(16, 4, 1.0), &pbd);
        assert_eq!((with.caught, with.failed.clone()), (None, None));
        assert_eq!(with.penetrations, 0, "{with:?}");
        assert!(with.max_stretch < 0.1, "{with:?}");
        let without = run(&folded(16, 4, 1.0).without_self_collision(), &pbd);
        assert!(without.penetrations > 0, "{without:?}");
    }

    #[test]
    fn the_implicit_methods_keep_the_folded_sheet_apart_inside_their_solve() {
        // Self-collision's pairs as terms of `pd`'s and Newton's objective:
        // only after their step, the pushes fought their stiff springs
        // (the 32² map cell: `pd-anderson` 78 edges through at 66 %
        // stretch, `newton` 377 at 133 %; here `pd` stretched 14.3 %).
        for name in ["pd", "pd-anderson", "newton"] {
            let method = bevy_cloth::methods::preset(name).unwrap().method;
            let with = run(&folded(16, 4, 1.0), &method);
            assert_eq!((with.caught, with.failed.clone()), (None, None), "{name}");
            assert_eq!(with.penetrations, 0, "{name}: {with:?}");
            assert!(with.max_stretch < 0.1, "{name}: {with:?}");
            let without = run(&folded(16, 4, 1.0).without_self_collision(), &method);
            assert!(without.penetrations > 0, "{name}: {without:?}");
        }
    }

    #[test]
    fn a_thin_setting_keeps_the_folded_sheet_apart_by_its_vertex_triangle_pairs() {
        // At 0.3 of the edges, vertex pairs alone let the layers through
        // (before the vertex–triangle pairs, 16²: `stiff` 395 edges at
        // 48 % stretch, stopped by the guard, `pd` 389, `newton` 222; 32²:
        // `chebyshev` 933, `pbd` 1677). `stiff` and the position-based
        // methods on the 32² sheet (`stiff` on the 16² one: the test
        // below).
        for (name, side) in [
            ("stiff", 32),
            ("chebyshev", 32),
            ("pbd", 32),
            ("pd", 16),
            ("newton", 16),
        ] {
            let method = bevy_cloth::methods::preset(name).unwrap().method;
            let with = run(&folded(side, 4, 1.0).thin(0.3), &method);
            assert_eq!((with.caught, with.failed.clone()), (None, None), "{name}");
            assert_eq!(with.penetrations, 0, "{name}: {with:?}");
            assert!(with.max_stretch < 0.1, "{name}: {with:?}");
        }
    }

    #[test]
    fn stiff_keeps_a_coarse_thin_fold_without_launching_its_corners() {
        // The 16² sheet at 0.3 and 0.4 of its 6.7 cm edges: in a crumpled
        // corner a vertex within the thickness of a triangle's plane, beside
        // the triangle, slid over it late in a step of 256 substeps (16×
        // refined near the ground) and its pair pushed it the step's whole
        // parting allowance (a quarter of the thickness, 5 mm) in one
        // substep: 80 m/s, the guard's stop at steps 59 and 76.
        let method = bevy_cloth::methods::preset("stiff").unwrap().method;
        for share in [0.3, 0.4] {
            let with = run(&folded(16, 4, 1.5).thin(share), &method);
            assert_eq!((with.caught, with.failed.clone()), (None, None), "{share}");
            assert_eq!(with.penetrations, 0, "{share}: {with:?}");
            assert!(with.max_stretch < 0.1, "{share}: {with:?}");
        }
    }

    #[test]
    fn edge_pairs_keep_the_thin_folds_crumpled_corners_from_crossing() {
        // Over 3 s at 0.3 of the edges, the 32² sheet's corners crumple at
        // the scale of its triangles, and under `chebyshev` two edges a row
        // and a column apart passed through each other with no vertex over
        // a triangle (2 edges through, with vertex–triangle pairs alone).
        let method = bevy_cloth::methods::preset("chebyshev").unwrap().method;
        let with = run(&folded(32, 4, 3.0).thin(0.3), &method);
        assert_eq!((with.caught, with.failed.clone()), (None, None));
        assert_eq!(with.penetrations, 0, "{with:?}");
        assert!(with.max_stretch < 0.1, "{with:?}");
    }

    #[test]
    fn pd_keeps_a_sheet_it_solves_by_multigrid_apart_once_it_lands() {
        // 64² is the size from which `pd` solves its global system by
        // multigrid. Its plain iterations (its Chebyshev acceleration is
        // off while pairs are near) left the pairs of the landing layers
        // pressed, and the pass after the step pushed them apart against
        // the springs: 23 edges through and 46 % stretch within half a
        // second. Anderson's acceleration takes over while there are pairs.
        let pd = bevy_cloth::methods::preset("pd").unwrap().method;
        let landing = run(&folded(64, 4, 0.5), &pd);
        assert_eq!((landing.caught, landing.failed.clone()), (None, None));
        assert_eq!(landing.penetrations, 0, "{landing:?}");
        assert!(landing.max_stretch < 0.1, "{landing:?}");
    }

    #[test]
    fn a_ball_through_a_sheet_is_seen_passing_when_nothing_stops_it() {
        let stiff = AnyMethod::Xpbd(XpbdSolver::STIFF);
        let held = run(&ball(24, 0.25), &stiff);
        assert_eq!((held.caught, held.passed, held.inside), (None, None, 0));
        // The same throw with the ball acting on nothing: it passes.
        let mut ghost = ball(24, 0.25);
        if let Some(Shape::Capsule(c)) = ghost.solids.get_mut(0) {
            c.radius = 1e-4;
        }
        let passed = run(&ghost, &stiff);
        assert!(passed.passed.is_some(), "{passed:?}");
        assert!(passed.cell(true).starts_with("✗ passed"));
    }
}
