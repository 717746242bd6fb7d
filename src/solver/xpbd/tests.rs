use bevy::math::{Affine3A, Vec3, Vec3A};

use super::*;
use crate::collision::{Capsule, Plane};
use crate::model::{ClothBuilder, ClothModel};
use crate::solver::exact::ExactSolver;
use crate::solver::{SpringStiffness, StepParams, max_stretch};
use crate::testing::run_from_rest;

fn lab() -> ClothModel {
    ClothBuilder::lab().build().unwrap()
}

fn stiff(k: f32, dt: f64) -> StepParams {
    StepParams {
        dt,
        stiffness: SpringStiffness::uniform(k),
        ..StepParams::LAB
    }
}

/// `model` from rest after `steps` steps of `method` with `contacts`
/// projected inside them.
fn run_with_contacts(
    method: XpbdSolver,
    model: &ClothModel,
    params: &StepParams,
    contacts: &[Shape],
    steps: usize,
    each: impl FnMut(&ClothState),
) -> ClothState {
    run_self_colliding(method, model, params, contacts, None, steps, each)
}

fn run_self_colliding(
    method: XpbdSolver,
    model: &ClothModel,
    params: &StepParams,
    contacts: &[Shape],
    self_collision: Option<crate::collision::SelfCollision>,
    steps: usize,
    mut each: impl FnMut(&ClothState),
) -> ClothState {
    let mut state = ClothState::at_rest(model, &Affine3A::IDENTITY);
    let mut ws = XpbdWorkspace::default();
    for _ in 0..steps {
        let input = StepInput {
            model,
            params,
            spheres: &[],
            contacts,
            contact_motion: &[],
            skin: None,
            self_collision: self_collision
                .map(crate::collision::self_contact::SelfCollisionInput::alone),
        };
        method.step_with(input, &mut state, &mut ws).unwrap();
        each(&state);
    }
    state
}

#[test]
fn the_substep_rate_gives_whole_counts_per_step() {
    let stiff = XpbdSolver::STIFF;
    assert_eq!(stiff.substeps(0.0333), 32);
    assert_eq!(stiff.substeps(1.0 / 30.0), 32);
    assert_eq!(stiff.substeps(1.0 / 60.0), 16);
    assert_eq!(stiff.substeps(0.1), 96);
    assert_eq!(stiff.substeps(1e-4), 1);
    for (n, dt) in [(1, 0.1), (7, 0.0333), (32, 1.0 / 60.0), (100, 1e-3)] {
        assert_eq!(stiff.with_substeps(n, dt).substeps(dt), n, "{n} at {dt}");
    }
}

#[test]
fn colours_share_no_vertex_and_hold_every_spring_once() {
    let model = ClothBuilder::lab_grid(9)
        .with_shear_springs()
        .with_bending_springs()
        .build()
        .unwrap();
    let mut colouring = Colouring::default();
    colouring.update(&model);
    let springs = model.topology().springs();
    let mut seen = colouring.order.clone();
    seen.sort_unstable();
    assert_eq!(seen, (0..springs.len() as u32).collect::<Vec<_>>());
    // A grid vertex has at most 12 springs: greedy needs at most 23
    // colours, and a grid far fewer.
    assert!(
        (2..=23).contains(&colouring.count()),
        "{}",
        colouring.count()
    );
    for c in 0..colouring.count() {
        let mut ends: Vec<u32> = colouring.order[colouring.colours[c]..colouring.colours[c + 1]]
            .iter()
            .flat_map(|&e| [springs[e as usize].a, springs[e as usize].b])
            .collect();
        let len = ends.len();
        ends.sort_unstable();
        ends.dedup();
        assert_eq!(ends.len(), len, "colour {c} has springs sharing a vertex");
    }
}

#[test]
fn a_cloth_at_rest_falls_as_symplectic_euler_at_the_substep() {
    // No pins, springs at rest length all along (every vertex moves alike):
    // n substeps of h give y = −g h² n(n+1)/2 and v = −g h n.
    let model = ClothBuilder::lab_grid(5).build().unwrap();
    let params = StepParams {
        damping: 1.0,
        ..stiff(1e6, 0.02)
    };
    let n = 8;
    let method = XpbdSolver::STIFF.with_substeps(n, 0.02);
    assert_eq!(method.substeps(0.02), n);
    let state = run_from_rest(&method, &model, &params, &[], 1);
    let h = 0.02 / f64::from(n);
    let g = 9.8;
    let drop = g * h * h * f64::from(n * (n + 1)) / 2.0;
    for (x, v) in state.positions.iter().zip(&state.velocities) {
        assert!((f64::from(x.y) + drop).abs() < 1e-5, "{x} against {drop}");
        assert!((f64::from(v.y) + g * h * f64::from(n)).abs() < 1e-4, "{v}");
        assert!(x.x.is_finite() && v.x.abs() < 1e-4 && v.z.abs() < 1e-4);
    }
}

#[test]
fn stiff_cloth_hangs_nearly_inextensible_and_pins_stay() {
    // k = 1e6 at a game's 60 Hz: Chebyshev and pd stop converging here (the
    // stability map), Newton holds the stretch to a fraction of a percent.
    let model = lab();
    let params = stiff(1e6, 1.0 / 60.0);
    let rest = ClothState::at_rest(&model, &Affine3A::IDENTITY);
    let state = run_from_rest(&XpbdSolver::STIFF, &model, &params, &[], 120);
    let stretch = max_stretch(&model, &state.positions);
    let newton = run_from_rest(&ExactSolver::BUDGET, &model, &params, &[], 120);
    let reference = max_stretch(&model, &newton.positions);
    assert!(stretch < 0.02, "stretch {stretch} (newton {reference})");
    for &p in model.pins() {
        assert_eq!(state.positions[p as usize], rest.positions[p as usize]);
    }
    // It fell: the far edge is metres below the pins, as Newton's.
    let low = |s: &ClothState| s.positions.iter().map(|x| x.y).fold(f32::MAX, f32::min);
    assert!(low(&state) < -8.0 && (low(&state) - low(&newton)).abs() < 1.0);
}

#[test]
fn extreme_stiffness_and_mass_stay_finite_and_bounded() {
    for (k, mass) in [(1e8f32, 1.0f32), (1e6, 1e-3), (1.0, 1.0)] {
        let model = ClothBuilder::lab()
            .with_mass_per_vertex(mass)
            .build()
            .unwrap();
        let params = stiff(k, 1.0 / 30.0);
        let state = run_from_rest(&XpbdSolver::STIFF, &model, &params, &[], 60);
        let stretch = max_stretch(&model, &state.positions);
        assert!(stretch.is_finite(), "k {k}, mass {mass}");
        // Soft springs stretch under the cloth's weight, stiff ones do not.
        if k >= 1e6 {
            assert!(stretch < 0.05, "k {k}, mass {mass}: {stretch}");
        }
        let speed = state
            .velocities
            .iter()
            .map(|v| v.length())
            .fold(0.0, f32::max);
        assert!(speed < 50.0, "k {k}, mass {mass}: {speed} m/s");
    }
}

#[test]
fn contacts_are_projected_inside_every_substep() {
    // The lab cloth swings down onto a sphere in front of its pinned edge
    // (z = 5) and piles on the ground below: after every step no vertex is
    // inside either, and stiff cloth is not strained by them.
    let model = lab();
    let params = stiff(1e6, 1.0 / 30.0);
    let sphere = Shape::Capsule(Capsule {
        a: Vec3A::new(0.0, -4.0, 6.5),
        b: Vec3A::new(0.0, -4.0, 6.5),
        radius: 2.7,
        friction: 0.0,
    });
    let ground = Shape::Plane(Plane {
        point: Vec3A::new(0.0, -8.0, 0.0),
        normal: Vec3A::Y,
        friction: 0.5,
    });
    let free = run_from_rest(&XpbdSolver::STIFF, &model, &params, &[], 90);
    let mut inside = 0;
    let state = run_with_contacts(
        XpbdSolver::STIFF,
        &model,
        &params,
        &[sphere, ground],
        90,
        |s| {
            inside += s
                .positions
                .iter()
                .filter(|&&x| {
                    sphere.contact(x, -1e-3).is_some() || ground.contact(x, -1e-3).is_some()
                })
                .count();
        },
    );
    assert_eq!(inside, 0);
    // It touches both: some vertex rests on each, within a millimetre.
    // (The sphere does not push the edges of a cloth without
    // self-collision: when it did, a 0.5 m edge over the 2.7 m sphere held
    // its ends 1.2 cm off it, away from the reference.)
    let touching = |shape: &Shape| {
        state
            .positions
            .iter()
            .filter(|&&x| shape.contact(x, 1e-3).is_some())
            .count()
    };
    assert!(touching(&sphere) > 0 && touching(&ground) > 0);
    let (in_contact, hanging) = (
        max_stretch(&model, &state.positions),
        max_stretch(&model, &free.positions),
    );
    assert!(
        in_contact < hanging + 0.01,
        "in contact {in_contact}, hanging {hanging}"
    );
}

#[test]
fn friction_holds_a_cloth_on_a_slope_that_a_frictionless_one_slides_down() {
    // A small free cloth laid on a 20° slope, a millimetre above it:
    // μ = 0.5 > tan 20° holds it.
    let angle = 20f32.to_radians();
    let normal = Vec3A::new(-angle.sin(), angle.cos(), 0.0);
    let down_slope = Vec3::new(-angle.cos(), -angle.sin(), 0.0);
    let origin = 1e-3 * Vec3::from(normal);
    let model = ClothBuilder::grid(
        5,
        5,
        origin,
        origin + 2.0 * down_slope,
        origin + 2.0 * Vec3::Z,
    )
    .build()
    .unwrap();
    let params = StepParams {
        damping: 1.0,
        ..stiff(1e5, 1.0 / 60.0)
    };
    let slide = |friction: f32| {
        let slope = Shape::Plane(Plane {
            point: Vec3A::ZERO,
            normal,
            friction,
        });
        let end = run_with_contacts(XpbdSolver::STIFF, &model, &params, &[slope], 60, |_| {});
        let rest = ClothState::at_rest(&model, &Affine3A::IDENTITY);
        let moved: Vec3A = end
            .positions
            .iter()
            .zip(&rest.positions)
            .map(|(x, r)| *x - *r)
            .sum();
        moved / end.positions.len() as f32
    };
    // One second: a frictionless cloth slides g sin 20° t²/2 ≈ 1.7 m.
    let (held, slid) = (slide(0.5), slide(0.0));
    // It falls the millimetre straight down (0.36 mm along the slope) and
    // sticks there.
    let settled = held - held.dot(normal) * normal;
    assert!(settled.length() < 4e-4, "held cloth moved {held}");
    let along = slid.dot(Vec3A::from(down_slope));
    assert!(
        (along - 1.68).abs() < 0.1,
        "frictionless cloth moved {slid}"
    );
    assert!(slid.dot(normal).abs() < 1e-2, "it left the slope: {slid}");
}

#[test]
fn a_kept_workspace_follows_the_cloth_its_stiffness_and_its_substep() {
    // The links (each spring's shares) are kept from step to step: a
    // change of stiffness, step, masses or pins between two steps gives
    // the same bits as a fresh workspace.
    let mut model = lab();
    let params = stiff(1e5, 1.0 / 60.0);
    let mut kept = XpbdWorkspace::default();
    let mut state = ClothState::at_rest(&model, &Affine3A::IDENTITY);
    let method = XpbdSolver::STIFF;
    method
        .step(&model, &mut state, &params, &[], &mut kept)
        .unwrap();
    let heavier: Vec<f32> = (0..model.vertex_count())
        .map(|i| 1.0 + (i % 7) as f32 * 0.5)
        .collect();
    type Change<'a> = &'a dyn Fn(&mut ClothModel, &mut StepParams);
    let changes: [Change; 4] = [
        &|_, p| p.stiffness = SpringStiffness::uniform(3e6),
        &|_, p| p.dt = 1.0 / 30.0,
        &|m, _| m.set_masses(heavier.clone()).unwrap(),
        &|m, _| m.set_pins(vec![0, 20, 220]).unwrap(),
    ];
    let mut params = params;
    for change in changes {
        change(&mut model, &mut params);
        let mut fresh_state = state.clone();
        method
            .step(&model, &mut state, &params, &[], &mut kept)
            .unwrap();
        method
            .step(
                &model,
                &mut fresh_state,
                &params,
                &[],
                &mut XpbdWorkspace::default(),
            )
            .unwrap();
        assert_eq!(state, fresh_state);
    }
}

#[test]
fn runs_are_bitwise_repeatable_and_zero_substeps_are_refused() {
    let model = lab();
    let params = stiff(1e7, 1.0 / 60.0);
    let a = run_from_rest(&XpbdSolver::STIFF, &model, &params, &[], 30);
    let b = run_from_rest(&XpbdSolver::STIFF, &model, &params, &[], 30);
    assert_eq!(a.positions, b.positions);
    assert_eq!(a.velocities, b.velocities);
    let mut state = ClothState::at_rest(&model, &Affine3A::IDENTITY);
    let before = state.clone();
    let refused = XpbdSolver::new(0).step(
        &model,
        &mut state,
        &params,
        &[],
        &mut XpbdWorkspace::default(),
    );
    assert_eq!(refused, Err(StepError::Params(ParamError::Iterations)));
    assert_eq!(state, before);
    let nan = StepParams {
        stiffness: SpringStiffness::uniform(f32::NAN),
        ..params
    };
    assert!(
        XpbdSolver::STIFF
            .step(&model, &mut state, &nan, &[], &mut XpbdWorkspace::default())
            .is_err()
    );
    assert_eq!(state, before);
}

#[test]
fn a_cloth_far_from_the_origin_keeps_its_velocity_to_f32_precision() {
    // Far below the origin and falling fast (a cloth falling freely for
    // 50 s): when the velocity was a difference of positions, the
    // positions' rounding over a short substep was velocity noise.
    let model = ClothBuilder::lab_grid(5).build().unwrap();
    let params = StepParams {
        damping: 1.0,
        ..stiff(1e6, 1.0 / 30.0)
    };
    let mut state = ClothState::at_rest(&model, &Affine3A::IDENTITY);
    for (x, v) in state.positions.iter_mut().zip(&mut state.velocities) {
        *x -= Vec3A::new(0.0, 1500.0, 0.0);
        *v = Vec3A::new(0.0, -30.0, 0.0);
    }
    let mut ws = XpbdWorkspace::default();
    XpbdSolver::STIFF
        .step(&model, &mut state, &params, &[], &mut ws)
        .unwrap();
    let expected = -30.0 - 9.8 / 30.0;
    for v in &state.velocities {
        assert!((v.y - expected).abs() < 1e-4, "{} against {expected}", v.y);
    }
}

/// A square cape `side` metres wide of `n×n` vertices, level at `y = 0`,
/// pinned along its edge `z = 0`, of `mass` kilograms.
fn cape(n: usize, side: f32, mass: f32) -> ClothModel {
    ClothBuilder::grid(
        n,
        n,
        Vec3::new(side / 2.0, 0.0, 0.0),
        Vec3::new(-side / 2.0, 0.0, 0.0),
        Vec3::new(side / 2.0, 0.0, side),
    )
    .with_total_mass(mass)
    .with_pins(0..n as u32)
    .build()
    .unwrap()
}

#[test]
fn tethers_take_back_the_sag_of_a_long_cape_and_hold_each_vertex_to_its_pin() {
    // A 64² cape of 1 kg at 60 Hz swings down from level: one sweep per
    // substep leaves its long columns stretched by what it cannot pass on.
    // Judged from its second second (the first swing's bottom is the
    // worst moment, and with tethers still a little over 5 %).
    let model = cape(64, 2.0, 1.0);
    let params = stiff(8000.0, 1.0 / 60.0);
    let worst = |method: XpbdSolver| {
        let mut worst = 0.0f32;
        let mut steps = 0;
        run_with_contacts(method, &model, &params, &[], 150, |state| {
            steps += 1;
            if steps > 60 {
                worst = worst.max(max_stretch(&model, &state.positions));
            }
        });
        worst
    };
    let loose = worst(XpbdSolver::STIFF.with_tethers(false));
    let tethered = worst(XpbdSolver::STIFF);
    assert!(loose > 0.08, "without tethers: {loose}");
    assert!(tethered < 0.05, "with tethers: {tethered}");

    // Every vertex ends within its limit of its pin, and the tether of a
    // vertex in column i hangs from the pin above it (a straight line).
    let state = run_with_contacts(XpbdSolver::STIFF, &model, &params, &[], 30, |_| {});
    let mut tethers = Tethers::default();
    tethers.update(&model);
    let slack = tethers::slack(&model, params.gravity, 8000.0);
    assert!(slack > 1.0 && slack < 1.01, "{slack}");
    let rest = model.topology().rest_positions();
    for (i, &(place, length)) in tethers.ties.iter().enumerate() {
        if i < 64 {
            assert!(length.is_infinite(), "a pin has no tether");
            continue;
        }
        assert_eq!(place as usize, i % 64, "vertex {i}");
        let pin = model.pins()[place as usize] as usize;
        assert!((length - rest[i].distance(rest[pin])).abs() < 1e-5);
        let reach = state.positions[i].distance(state.positions[pin]);
        assert!(reach <= length * slack * (1.0 + 1e-5), "vertex {i}");
    }
}

#[test]
fn a_tether_follows_the_cloth_round_a_notch_and_along_a_curved_rest_shape() {
    // An L of three squares pinned at the end of one arm: the other arm's
    // far corner is reached round the inner corner, not in a straight line
    // across the missing square.
    let positions = vec![
        Vec3::new(0.0, 0.0, 0.0),
        Vec3::new(1.0, 0.0, 0.0),
        Vec3::new(2.0, 0.0, 0.0),
        Vec3::new(0.0, 1.0, 0.0),
        Vec3::new(1.0, 1.0, 0.0),
        Vec3::new(2.0, 1.0, 0.0),
        Vec3::new(0.0, 2.0, 0.0),
        Vec3::new(1.0, 2.0, 0.0),
    ];
    // Squares (0,1,4,3), (1,2,5,4), (3,4,7,6): no square at (1..2, 1..2).
    let indices = vec![0, 1, 4, 0, 4, 3, 1, 2, 5, 1, 5, 4, 3, 4, 7, 3, 7, 6];
    let model = ClothBuilder::from_triangles(positions, indices)
        .with_pins([2])
        .build()
        .unwrap();
    let mut tethers = Tethers::default();
    tethers.update(&model);
    // Vertex 7 at (1, 2): straight to (2, 0) is √5 ≈ 2.24 across the
    // notch; along the springs (7→4→5→2) it is 3.
    let (_, length) = tethers.ties[7];
    assert!((length - 3.0).abs() < 1e-5, "{length}");
    // Vertex 4 at (1, 1): no spring joins it to 2; the path 4→5→2 is 2,
    // 41 % longer than the straight √2 (past a grid's zig-zag): the path.
    let (_, length) = tethers.ties[4];
    assert!((length - 2.0).abs() < 1e-5, "{length}");

    // A rest shape bent into a half cylinder: a chord is shorter than the
    // cloth between, so the tether keeps the path along the springs.
    let n = 9;
    let model = ClothBuilder::grid(
        n,
        n,
        Vec3::ZERO,
        Vec3::new(1.0, 0.0, 0.0),
        Vec3::new(0.0, 0.0, 1.0),
    )
    .build()
    .unwrap();
    let bent: Vec<Vec3> = model
        .topology()
        .rest_positions()
        .iter()
        .map(|p| {
            let a = p.z * std::f32::consts::PI;
            Vec3::new(
                p.x,
                a.sin() / std::f32::consts::PI,
                -a.cos() / std::f32::consts::PI,
            )
        })
        .collect();
    let model = ClothBuilder::from_triangles(bent, model.topology().triangles().concat())
        .with_pins([0])
        .build()
        .unwrap();
    let mut tethers = Tethers::default();
    tethers.update(&model);
    let rest = model.topology().rest_positions();
    // The vertex across the arc from the pin (x = 0, z = 1): the arc is
    // about 1 long, its chord 2/π.
    let far = n * (n - 1);
    let (_, length) = tethers.ties[far];
    assert!(length > 0.99, "{length}");
    assert!(rest[far].distance(rest[0]) < 0.7);
}

#[test]
fn tethers_never_bind_on_cloth_their_slack_lets_stretch() {
    // The lab's cloth (441 kg at k = 8000) stretches by a third where it
    // hangs, far within its slack: with tethers or without, the same bits.
    let model = lab();
    let params = StepParams::LAB;
    let with = run_with_contacts(XpbdSolver::STIFF, &model, &params, &[], 60, |_| {});
    let without = run_with_contacts(
        XpbdSolver::STIFF.with_tethers(false),
        &model,
        &params,
        &[],
        60,
        |_| {},
    );
    assert_eq!(with.positions, without.positions);
    assert!(max_stretch(&model, &with.positions) > 0.1);
}

#[test]
fn pins_move_through_the_substeps_unless_they_were_teleported() {
    // The lab cloth after a second; then its pins move by `jump` along x
    // in one step (velocity: the jump over the step), or jump there with
    // no velocity: a move is spread over the substeps, a teleport (half
    // the cloth's size or more) is not.
    let model = lab();
    let params = StepParams::LAB;
    let settled = run_with_contacts(XpbdSolver::STIFF, &model, &params, &[], 30, |_| {});
    let after_with = |method: XpbdSolver, jump: f32, with_velocity: bool| {
        let mut state = settled.clone();
        for &p in model.pins() {
            state.positions[p as usize].x += jump;
            state.velocities[p as usize] = if with_velocity {
                Vec3A::new(jump / params.dt as f32, 0.0, 0.0)
            } else {
                Vec3A::ZERO
            };
        }
        let mut ws = XpbdWorkspace::default();
        let input = StepInput {
            model: &model,
            params: &params,
            spheres: &[],
            contacts: &[],
            contact_motion: &[],
            skin: None,
            self_collision: None,
        };
        method.step_with(input, &mut state, &mut ws).unwrap();
        state.positions
    };
    let after = |jump, with_velocity| after_with(XpbdSolver::STIFF, jump, with_velocity);
    // Moved 0.5: the pins reach their place at the last substep.
    let spread = after(0.5, true);
    assert_ne!(spread, after(0.5, false));
    for &p in model.pins() {
        assert_eq!(
            spread[p as usize],
            settled.positions[p as usize] + Vec3A::X * 0.5
        );
    }
    // Teleported 100: as if it had jumped, and the cloth, far outside its
    // tethers' reach, dragged by its springs alone (not yanked back by the
    // tethers in one substep).
    assert_eq!(after(100.0, true), after(100.0, false));
    let loose = XpbdSolver::STIFF.with_tethers(false);
    assert_eq!(after(100.0, false), after_with(loose, 100.0, false));
}

#[test]
fn refinement_grows_with_stiffness_over_mass_in_powers_of_two_up_to_its_cap() {
    let m = XpbdSolver::STIFF;
    // 32 substeps of 1/30 s: h = 1/960 s, κ = k/(960² m).
    let at = |k: f32, mass: f32| m.refinement(32, 1.0 / 30.0, k, mass);
    assert_eq!(at(8000.0, 1.0), 1, "the lab's κ ≈ 0.009");
    assert_eq!(at(1e5, 1.0), 1);
    assert_eq!(at(1e6, 1.0), 2, "κ ≈ 1.09");
    assert_eq!(at(4e6, 1.0), 8, "κ ≈ 4.3");
    assert_eq!(at(1e7, 1.0), 16, "κ ≈ 10.9");
    assert_eq!(at(1e8, 1.0), 16, "capped");
    assert_eq!(at(1e6, 0.1), 16, "lighter vertices, larger κ");
    assert_eq!(at(1e6, 0.0), 16, "a massless cloth takes the cap");
    assert_eq!(at(f32::NAN, 1.0), 1);
    assert_eq!(
        m.with_max_refinement(1)
            .refinement(32, 1.0 / 30.0, 1e8, 1.0),
        1
    );
    assert_eq!(
        m.with_max_refinement(0).validate(),
        Err(ParamError::Iterations)
    );
    // The garment setting: the preset refined at most 4×.
    let g = XpbdSolver::GARMENT;
    assert_eq!(g.refinement(32, 1.0 / 30.0, 1e7, 1.0), 4, "κ ≈ 10.9");
    assert_eq!(g.refinement(32, 1.0 / 30.0, 1e6, 1.0), 2, "below the cap");
    assert_eq!(g.with_max_refinement(16), XpbdSolver::STIFF);
}

/// The lab's sphere, in front of the lab cloth's pinned edge.
fn lab_sphere(y: f32) -> Shape {
    Shape::Capsule(Capsule {
        a: Vec3A::new(0.0, y, 4.0),
        b: Vec3A::new(0.0, y, 4.0),
        radius: 2.7,
        friction: 0.0,
    })
}

#[test]
fn only_steps_near_a_collider_are_refined() {
    let model = lab();
    let substeps = |k: f32, contacts: &[Shape]| {
        let params = stiff(k, 1.0 / 30.0);
        let mut state = ClothState::at_rest(&model, &Affine3A::IDENTITY);
        let mut ws = XpbdWorkspace::default();
        let input = StepInput {
            model: &model,
            params: &params,
            spheres: &[],
            contacts,
            contact_motion: &[],
            skin: None,
            self_collision: None,
        };
        XpbdSolver::STIFF
            .step_with(input, &mut state, &mut ws)
            .unwrap()
            .iterations
    };
    // The cloth starts level at y = 0, the sphere's top 5 cm below it.
    let near = lab_sphere(-2.75);
    assert_eq!(substeps(1e7, &[near]), 32 * 16);
    assert_eq!(substeps(1e6, &[near]), 32 * 2);
    assert_eq!(substeps(8000.0, &[near]), 32, "the lab pays nothing");
    assert_eq!(
        substeps(1e7, &[lab_sphere(-4.0)]),
        32,
        "the lab's sphere is 1.3 below"
    );
    assert_eq!(substeps(1e7, &[]), 32, "nor does a cloth hanging free");
    assert_eq!(
        substeps(1e7, &[lab_sphere(-100.0)]),
        32,
        "nor one far above a collider"
    );
    let far_plane = Shape::Plane(Plane {
        point: Vec3A::new(0.0, -100.0, 0.0),
        normal: Vec3A::Y,
        friction: 0.0,
    });
    assert_eq!(substeps(1e7, &[far_plane]), 32);
    // The cloth starts level at y = 0: a ground just below it is near.
    let near_plane = Shape::Plane(Plane {
        point: Vec3A::new(0.0, -0.05, 0.0),
        normal: Vec3A::Y,
        friction: 0.0,
    });
    assert_eq!(substeps(1e7, &[near_plane]), 32 * 16);
}

#[test]
fn stiff_cloth_falling_onto_a_sphere_is_not_strained_on_impact() {
    // k = 1e7 on the lab's 1 kg vertices at 30 Hz: κ ≈ 11 at 960 substeps
    // per second. Unrefined, the springs next to the contacts stretch on
    // impact far beyond the same cloth's stretch hanging free.
    let model = lab();
    let params = stiff(1e7, 1.0 / 30.0);
    let sphere = lab_sphere(-4.0);
    let worst = |method: XpbdSolver, contacts: &[Shape]| {
        let mut worst = 0.0f32;
        run_with_contacts(method, &model, &params, contacts, 90, |s| {
            worst = worst.max(max_stretch(&model, &s.positions));
        });
        worst
    };
    let hanging = worst(XpbdSolver::STIFF, &[]);
    let refined = worst(XpbdSolver::STIFF, &[sphere]);
    let unrefined = worst(XpbdSolver::STIFF.with_max_refinement(1), &[sphere]);
    assert!(
        refined < hanging + 0.01,
        "refined {refined}, hanging {hanging}"
    );
    assert!(
        unrefined > hanging + 0.01,
        "unrefined {unrefined}, hanging {hanging}: the test no longer sees the strain"
    );
}

#[test]
fn a_cotton_cape_swinging_onto_a_body_keeps_its_length_with_the_refinement() {
    // A 2 m, 1 kg cape of 32² cotton at 60 Hz, hung by its top edge,
    // starts tilted forward and swings back onto a body capsule behind it
    // (κ = k h²/m ≈ 6 at 960 substeps per second: 8× near the body). One
    // sweep per substep left it stretched past 5 % where it meets the body.
    use crate::model::ClothMaterial;
    let n = 32;
    let model = ClothBuilder::grid(
        n,
        n,
        Vec3::new(-1.0, 0.0, 0.0),
        Vec3::X * 2.0,
        Vec3::NEG_Y * 2.0,
    )
    .with_pins(0..n as u32)
    .with_material(ClothMaterial::COTTON)
    .build()
    .unwrap();
    let params = StepParams {
        dt: 1.0 / 60.0,
        stiffness: ClothMaterial::COTTON.spring_stiffness(&model),
        ..StepParams::LAB
    };
    let body = Shape::Capsule(Capsule {
        a: Vec3A::new(0.0, -1.6, -0.35),
        b: Vec3A::new(0.0, -0.2, -0.35),
        radius: 0.3,
        friction: 0.3,
    });
    let worst = |method: XpbdSolver| {
        let mut state = ClothState::at_rest(&model, &Affine3A::IDENTITY);
        for (x, r) in state
            .positions
            .iter_mut()
            .zip(model.topology().rest_positions())
        {
            *x = Vec3A::new(r.x, 0.7 * r.y, -0.7 * r.y);
        }
        let mut ws = XpbdWorkspace::default();
        let mut worst = 0.0f32;
        for _ in 0..300 {
            let input = StepInput {
                model: &model,
                params: &params,
                spheres: &[],
                contacts: &[body],
                contact_motion: &[],
                skin: None,
                self_collision: None,
            };
            method.step_with(input, &mut state, &mut ws).unwrap();
            worst = worst.max(max_stretch(&model, &state.positions));
        }
        worst
    };
    let (refined, unrefined) = (
        worst(XpbdSolver::STIFF),
        worst(XpbdSolver::STIFF.with_max_refinement(1)),
    );
    assert!(refined < 0.05, "refined {refined}");
    assert!(
        unrefined > 0.05,
        "unrefined {unrefined}: the test no longer sees it"
    );
}

/// A 1 m sheet of 24² cotton standing on its edge, a little tilted,
/// crumples onto the ground for three seconds: the most mesh edges through
/// its own triangles at any step, and its largest stretch.
fn crumple(self_collision: Option<crate::collision::SelfCollision>) -> (usize, f32) {
    use crate::collision::self_contact::{IntersectionCheck, count_intersections};
    use crate::model::ClothMaterial;
    let n = 24;
    let model = ClothBuilder::grid(
        n,
        n,
        Vec3::new(0.0, 0.02, 0.0),
        Vec3::new(0.0, 1.0, 0.15),
        Vec3::new(1.0, 0.02, 0.0),
    )
    .with_material(ClothMaterial::COTTON)
    .build()
    .unwrap();
    let params = StepParams {
        dt: 1.0 / 60.0,
        stiffness: ClothMaterial::COTTON.spring_stiffness(&model),
        ..StepParams::LAB
    };
    let ground = Shape::Plane(Plane {
        point: Vec3A::ZERO,
        normal: Vec3A::Y,
        friction: 0.5,
    });
    let self_collision = self_collision.map(|mut sc| {
        if sc.thickness == 0.0 {
            sc.thickness = crate::collision::SelfCollision::for_model(&model).thickness;
        }
        sc
    });
    let mut check = IntersectionCheck::default();
    let rest = ClothState::at_rest(&model, &Affine3A::IDENTITY);
    assert_eq!(count_intersections(&model, &rest.positions, &mut check), 0);
    let (mut worst, mut stretch) = (0, 0.0f32);
    run_self_colliding(
        XpbdSolver::STIFF,
        &model,
        &params,
        &[ground],
        self_collision,
        180,
        |s| {
            let now = count_intersections(&model, &s.positions, &mut check);
            worst = worst.max(now);
            stretch = stretch.max(max_stretch(&model, &s.positions));
        },
    );
    (worst, stretch)
}

#[test]
fn self_collision_keeps_a_crumpling_sheet_from_passing_through_itself() {
    let (without, _) = crumple(None);
    assert!(without > 0, "the scene must fold through itself without it");
    let sc = crate::collision::SelfCollision {
        thickness: 0.0,
        friction: 0.3,
    };
    let (with, stretch) = crumple(Some(sc));
    println!("most intersections {without} without, {with} with; max stretch {stretch}");
    assert_eq!(with, 0, "{without} intersections without self-collision");
    assert!(stretch < 0.1, "max stretch {stretch}");
}

#[test]
fn friction_carries_a_cloth_on_a_solid_that_slides_under_it() {
    // A small cloth resting on a wide box (a tray) that slides along x at
    // 1 m/s for half a second: with μ = 1 it rides along, without it stays
    // where it was. Friction acts on its motion relative to the box (on
    // its own motion, it held the cloth still while the box slid away).
    let model = ClothBuilder::grid(
        5,
        5,
        Vec3::new(-0.2, 0.0, -0.2),
        Vec3::new(0.2, 0.0, -0.2),
        Vec3::new(-0.2, 0.0, 0.2),
    )
    .build()
    .unwrap();
    let params = StepParams {
        damping: 1.0,
        ..stiff(1e4, 1.0 / 60.0)
    };
    let ride = |friction: f32| {
        let dt = params.dt as f32;
        let speed = Vec3A::new(1.0, 0.0, 0.0);
        let mut tray = Shape::Cuboid(crate::collision::Cuboid {
            center: Vec3A::new(0.0, -0.1, 0.0),
            axes: [Vec3A::X, Vec3A::Y, Vec3A::Z],
            half_extents: Vec3A::new(2.0, 0.1, 2.0),
            friction,
        });
        let mut state = ClothState::at_rest(&model, &Affine3A::IDENTITY);
        let mut ws = XpbdWorkspace::default();
        for _ in 0..30 {
            tray = tray.translated(speed * dt);
            let input = StepInput {
                model: &model,
                params: &params,
                spheres: &[],
                contacts: &[tray],
                contact_motion: &[speed * dt],
                skin: None,
                self_collision: None,
            };
            XpbdSolver::STIFF
                .step_with(input, &mut state, &mut ws)
                .unwrap();
        }
        let mean: Vec3A = state.positions.iter().sum::<Vec3A>() / state.positions.len() as f32;
        (mean, max_stretch(&model, &state.positions))
    };
    let ((carried, stretch), (left, _)) = (ride(1.0), ride(0.0));
    // Kinetic friction brings it up to the tray's speed in v/(μg): it
    // lags v²/(2μg) = 5.1 cm behind the tray's 0.5 m.
    assert!(
        (carried.x - 0.449).abs() < 0.01,
        "the cloth on the tray moved {carried}"
    );
    assert!(stretch < 0.01, "stretched {stretch}");
    assert!(left.x.abs() < 0.02, "the frictionless cloth moved {left}");
    // It stays on the tray, not in it.
    assert!(carried.y > -1e-3 && left.y > -1e-3, "{carried} {left}");
}
