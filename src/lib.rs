//! # bevy_cloth
//!
//! Cloth simulation for the [Bevy](https://bevy.org) game engine, with the
//! methods of two course specifications implemented in full:
//!
//! - the GAMES103 cloth lab: implicit Euler by a diagonal-Hessian
//!   Newton/Jacobi iteration with Chebyshev acceleration; position-based
//!   dynamics with Jacobi strain limiting; sphere collision by impulse
//!   projection;
//! - a mass-spring assignment: symplectic Euler, linearly implicit Euler
//!   (`A = M − h²K`) with sparse matrices solved by conjugate gradients or a
//!   sparse LDLᵀ factorisation, stretch/shear/bending springs, and penalty
//!   sphere collision inside the solve.
//!
//! # Getting Started
//!
//! ## Add the Dependency
//!
//! ```toml
//! [dependencies]
//! bevy_cloth = "0.1"
//! ```
//!
//! ## Feature Flags
//!
//! | Feature | Description | Default feature |
//! |---|---|---|
//! | `render` | `render`: `ClothRenderPlugin` writes cloth positions and normals into their meshes once per frame. Needs Bevy's `bevy_mesh` and `bevy_camera` only (no renderer or window: the game brings its own). | Yes |
//! | `picking` | `drag`: `DragPlugin` drags entities with the mouse (Bevy's picking). | No |
//! | `egui` | `ui`: `ClothInspectorPlugin`, a panel to switch methods and tune cloths live, with pause, step and reset (`bevy_egui`). | No |
//! | `avian` | `avian`: `AvianCollisionPlugin` (in `ClothPlugins`): cloths collide with every avian3d 0.7 `Collider` by its closest-point query, with its `Friction`, after the step; balls, capsules, cuboids and half-spaces also inside it, as the crate's own colliders; one-way (the cloth does not push rigid bodies). | No |
//! | `serialize` | serde's `Serialize` and `Deserialize` for [`ClothSnapshot`] (a game's save files; serde is in Bevy's tree already). | No |
//!
//! With default features a game builds the simulation and the mesh
//! write-back only. With `default-features = false` the crate builds only the
//! simulation: Bevy's `std`, `multi_threaded`, `bevy_log`, `bevy_asset` and
//! `bevy_mesh` features, and `faer` (sparse linear algebra, without its rayon
//! thread pool). The report, the stability map and the performance page are
//! a separate crate of the workspace (`bevy_cloth_report`).
//!
//! ## Add the Plugins
//!
//! ```
//! use bevy::prelude::*;
//! use bevy_cloth::prelude::*;
//!
//! fn setup(mut commands: Commands) {
//!     // The lab's cloth: 21×21 vertices over 10×10 units, pinned at 0 and 20.
//!     let cloth = Cloth::build(ClothBuilder::lab()).expect("valid cloth");
//!     commands.spawn((cloth, ImplicitSolver::chebyshev(32, 0.995), Transform::default()));
//!     // The lab's sphere.
//!     commands.spawn((SphereCollider::new(2.7), Transform::from_xyz(0.0, -4.0, 4.0)));
//! }
//!
//! let mut app = App::new();
//! app.add_plugins((MinimalPlugins, ClothPlugins::default()))
//!     .insert_resource(Time::<Fixed>::from_seconds(0.0333))
//!     .add_systems(Startup, setup);
//! app.update();
//! ```
//!
//! A game that needs only one pipeline adds only its plugin (it brings
//! [`ClothCorePlugin`] along): `app.add_plugins(PbdPlugin::default())`.
//!
//! # Table of Contents
//!
//! ## Cloths
//! - [`ClothBuilder`](model::ClothBuilder): the lab's grid, any triangle list, a Bevy `Mesh`
//!   (welded along its UV seams, written back unwelded); [`ClothFromMesh`]: a
//!   cloth from a mesh asset still loading (glTF), built when it is ready;
//!   [`model::mesh_vertices_where`]: pins painted in a vertex attribute
//! - [`Cloth`], [`ClothParams`], [`ClothStats`]
//! - Errors: [`ClothBuildError`](model::ClothBuildError), [`ParamError`](solver::ParamError)
//!
//! ## Methods
//!
//! A method is a settings type implementing [`solver::Method`], in its own
//! solver folder; the method table ([`methods`]) makes each a component, a
//! plugin and a variant of [`AnyMethod`], and [`PRESETS`] names each
//! method's interactive settings once (`jacobi`, `chebyshev`, `pbd`, …: the
//! names the panel, `--method`, [`ClothStats::method`], the report and the
//! perf page use).
//!
//! | Component / plugin | Method | Spec | Solver |
//! |---|---|---|---|
//! | [`ImplicitSolver`] / [`ImplicitPlugin`] | implicit Euler, diagonal-Hessian Jacobi, optional Chebyshev | lab part 1 | [`solver::implicit`] |
//! | [`PbdSolver`] / [`PbdPlugin`] | position-based dynamics, Jacobi strain limiting | lab part 2 | [`solver::pbd`] |
//! | [`SymplecticSolver`] / [`SymplecticPlugin`] | symplectic Euler (`A = M`) | assignment | [`solver::symplectic`] |
//! | [`LinearImplicitSolver`] / [`LinearImplicitPlugin`] | linearly implicit Euler, sparse CG or LDLᵀ | assignment | [`solver::linear`] |
//! | [`ProjectiveSolver`] / [`ProjectivePlugin`] | projective dynamics (local–global) on the implicit-Euler objective, Chebyshev- (`pd`: at most 10 iterations, stopping early once its estimated error is 1 % of the step's motion) or Anderson-accelerated (`pd-anderson`), factorised once (or a multigrid V-cycle per iteration on large cloths: [`GlobalSolve`]) | Liu et al. 2013, Wang 2015, Peng et al. 2018 | [`solver::projective`] |
//! | [`ExactSolver`] / [`ExactPlugin`] | exact implicit Euler: Newton, sparse Cholesky, line search; to 1e-9 (`exact`) or on a budget of 16 iterations to 1e-5 (`newton`) | the reference | [`solver::exact`] |
//! | [`XpbdSolver`] / [`XpbdPlugin`] | XPBD with small steps (`stiff`: 960 substeps per second of one Gauss–Seidel sweep, up to 16× near a collider), contacts projected and pins moved in every substep, tethers to the pins, optionally chains of stretch springs solved whole ([`XpbdSolver::chains`]) | Macklin et al. 2016, 2019; Kim et al. 2012 | [`solver::xpbd`] |
//!
//! **Which preset for what** (from the stability map, the report and the
//! perf page; the README has the numbers). What decides is `k·dt²/m`, a
//! spring's stiffness against a vertex's inertia over one step: the lab at
//! 30 Hz is about 9; a 1 kg cape of [`ClothMaterial::COTTON`](model::ClothMaterial::COTTON) at 60 Hz is
//! about 500 at 16² and 9 000 at 64².
//!
//! | You want | Preset |
//! |---|---|
//! | the lab's look, soft cloth (`k·dt²/m` up to ~10: `k` up to ~1e4 on the lab cloth at 30 Hz) | `chebyshev` |
//! | a game's cloth: real mass, stiff, in contact, at a frame rate (the default, [`AnyMethod::default`]) | `stiff` (against the physical reference: every cell of the map, hanging, falling onto the sphere and draped on it; up to 16× its substeps near a collider where `k·h²/m` > 1; 2.8–3.4× Chebyshev-32 at 21² to 256² on one thread) |
//! | stiffer cloth, implicit Euler at interactive cost (`k` up to 1e5 on the lab cloth at 60 Hz, 1e4 at 30 Hz) | `pd` |
//! | stiff cloth, implicit Euler, small to mid-size | `pd-anderson` (37 of the map's 48 hanging cells) |
//! | the implicit-Euler answer at any stiffness, small cloths (≤ ~51²) | `newton` (every hanging and draped cell of the map, 45 of 48 onto the sphere; its cost per step: `docs/perf.md`) |
//! | large cloths (≥ 101²) at a frame rate | `chebyshev` on 2 threads, or `stiff` / `pd` for stiffer cloth |
//! | the reference | `exact` |
//!
//! ## Collision
//! - [`SphereCollider`] / [`SphereCollisionPlugin`] ([`collision`]):
//!   [`SphereResponse::Projection`] (the lab's impulse projection, after the
//!   step) or [`SphereResponse::Penalty`] (the assignment's penalty force,
//!   inside the step)
//! - [`PlaneCollider`] (a half-space: the ground, a slope, through its
//!   entity with the normal along its local `+Y`), [`CapsuleCollider`] and
//!   [`CuboidCollider`] / [`ShapeCollisionPlugin`]: projected after the step
//!   with Coulomb friction ([`collision::project_shapes`], swept:
//!   [`collision::project_swept`]), or, with
//!   [`ContactResponse::Penalty`], a penalty force inside the step like the
//!   assignment's sphere ([`collision::PenaltySurface::Shape`]); every method.
//! - The projected solids also reach the method inside its step
//!   ([`solver::StepInput::contacts`]): `stiff` ([`XpbdSolver`]) projects
//!   them in every substep, `newton` and `exact` ([`ExactSolver::contacts`])
//!   and `pd` and `pd-anderson` ([`ProjectiveSolver::contacts`]) add them to
//!   their objective as penalties, so stiff cloth in contact is not strained
//!   by the projection after the step; the lab's and the assignment's
//!   methods leave them to that projection, as their specifications do.
//! - [`SelfCollision`] (on a cloth entity, opt-in; a cloth without it pays
//!   nothing): every pair of the cloth's vertices is kept a thickness apart
//!   ([`collision::self_contact`]; [`SelfCollision::for_model`] takes 0.9
//!   of the shortest rest edge, where the surface cannot pass through
//!   itself). `stiff` keeps them apart in every substep, PBD after each of
//!   its iterations; `pd`, `pd-anderson`, `newton` and `exact` make the
//!   pairs penalty terms of their objective, then resolve them after the
//!   step; every other method gets it after its step, which helps but does not guarantee it (a
//!   vertex can move further than the thickness in one step). A bad setting
//!   is a [`SelfCollisionError`], logged once, and the cloth runs without
//!   it. Two cloths that both have one keep off each other: each step sees
//!   the other cloths where they were at its start
//!   ([`collision::self_contact::OtherVertex`]), and a joint pass after all
//!   steps ([`collision::self_contact::ClothLayers`]) pushes apart what the
//!   steps could not see (for `stiff`, the vertices around each one it
//!   pushed pulled after it, so that a push is not all one edge's stretch,
//!   and then its own edges through its own triangles taken back out, as
//!   its step ends with).
//! - **No tunnelling** ([`collision::swept`]): the projection after the step
//!   follows each vertex relative to its collider's motion over the step,
//!   from where it was at the step's start; one that went through (a ball
//!   thrown through the cloth, a vertex falling through a thin box) is put
//!   back where it entered. `stiff` also moves the colliders through its
//!   substeps ([`solver::StepInput::contact_motion`]) and lets boxes push
//!   the cloth's edges there, not only its vertices, so cloth drapes over
//!   a box's edge instead of cutting it (a smooth solid is cut only by
//!   chords between vertices on its surface, as the reference cuts it).
//!
//! ## Pins
//! - Pins given to [`ClothBuilder::with_pins`](model::ClothBuilder::with_pins)
//!   follow the cloth's own entity; [`ClothAttachments`] hands any vertices
//!   ([`ClothModel::vertices_where`](model::ClothModel::vertices_where) picks
//!   them by rest position) to other entities with an offset, attached,
//!   detached and re-attached at run time.
//!
//! ## Character cloth
//! - [`ClothSkin`] / [`CharacterClothPlugin`] ([`character`]): a cloth held
//!   near an animated shape, per vertex: max distance from its skinned
//!   position, a backstop sphere behind it along the skinned normal, an
//!   anim drive towards it, and tethers to its nearest pin (after the step
//!   for every method; inside every substep for `stiff`,
//!   [`solver::SkinInput`]). The pose comes from the game or from
//!   [`Skinning`]: linear blend skinning of a
//!   [`SkinnedMesh`](bevy::mesh::skinning::SkinnedMesh)'s joints on the CPU,
//!   with the cloth's pins on the skin.
//! - [`ClothInertia`] ([`character::inertia`]): how much of an anchor's
//!   (the character's root) velocity and acceleration the cloth feels, and
//!   a rigid move with the anchor when it jumps further than a teleport
//!   distance in one step; every method. `examples/cape.rs` dresses a
//!   character made in code in a cape and a skirt.
//!
//! ## Wind and air
//! - [`Wind`] (a resource: mean velocity, deterministic gusts) /
//!   [`WindPlugin`]: per-triangle drag and lift ([`aero`]), coefficients per
//!   cloth in [`ClothAerodynamics`]; an explicit external force of the step,
//!   with its damping part implicit, for every method.
//!
//! ## The assignment's golden first step
//!
//! The assignment prints `A` and `b` of the first step of its 2×2 cloth
//! (`h = 5e-3`, gravity `(0, −9.8, 0)`, total mass 0.1, `E = 10`) without
//! saying where the grid lies or which particles are fixed. The matrix
//! determines it up to symmetry: it is 6×6, so two of the four particles are
//! fixed; the `y` diagonal is exactly `m = 0.025` (no stiffness along `y`), so
//! every spring lies in a horizontal plane; `xx` and `zz` are both
//! `m + 1.5·h²E = 0.025375` and the `xz` coupling is `±h²E/2`, which a
//! stretch spring plus a 45° shear spring to a fixed particle give when the
//! grid is square; the `−h²E` coupling between the two free particles' `x`
//! makes them a row along `x`. So: a square horizontal grid, the two
//! particles of one row fixed. [`ClothBuilder::assignment`](model::ClothBuilder::assignment)
//! builds it (0.5×0.5 at `y = 0.5`, row 0 fixed) and a test reproduces every
//! printed entry to its four decimals.
//!
//! ## Rendering and UI (optional)
//! - `render::ClothRenderPlugin`, `render::cloth_mesh` (feature `render`)
//! - `drag::DragPlugin` (feature `picking`)
//! - `ui::ClothInspectorPlugin` (feature `egui`)
//!
//! ## Stability
//! - [`ClothGuard`]: the divergence guard's bounds and policy per cloth
//!   ([`solver::guard`]); [`ClothDiverged`] reports what it did.
//! - Convergence: every step of Jacobi, Chebyshev and projective dynamics
//!   estimates its distance from the exact implicit-Euler step
//!   ([`solver::StepReport::relative_error`], [`ClothStats::converged`]); a
//!   cloth whose step ends far from it gets [`ClothNotConverged`] once.
//! - Mistakes are typed, not silent: invalid parameters, settings or state
//!   are [`ClothStatus::Invalid`] with the [`solver::StepError`]; a cloth whose
//!   method has no plugin (or that has no method) is [`ClothStatus::NoMethod`].
//! - The stability map (crate `bevy_cloth_report`): stiff and extreme
//!   scenarios classified against the exact method, and symplectic Euler's
//!   step limit `2/ω_max`.
//!
//! ## Performance
//! - Every iteration of the spring-based methods is two passes: one over
//!   springs in packed SIMD, which computes each spring's term once (four
//!   springs at a time in glam's `Vec4`, or eight with AVX2, chosen at run
//!   time and giving the same bits: `solver::engine::simd`); one over vertices, which gathers its
//!   springs' terms ([`model::Adjacency::by_side`], or fixed-length
//!   [`model::Adjacency::padded`] rows: no scattered writes, no
//!   atomics) and updates the vertex in the same loop. Both passes are bound
//!   by instructions at the lab's size, so neither checks an index per
//!   read: the model's topology checked every index when it was built, and
//!   each pass asserts once that its buffers are that long. No allocation or
//!   hashing per step; sparse patterns and factorisations are reused.
//! - A cloth whose springs form a stencil — a grid numbered row by row, as
//!   every builder's, so that each spring `(a, a + o)` belongs to one of at
//!   most eight offset families `o` — runs the implicit iteration (Jacobi,
//!   Chebyshev), PBD's strain limiting, symplectic Euler's spring forces
//!   and projective dynamics' local step on structure-of-arrays kernels
//!   instead (`solver::engine::stencil`, built with the
//!   topology, invisible to users): a
//!   family's springs are two contiguous runs of positions, so both passes
//!   are plain streams the compiler vectorises, compiled for SSE2/NEON,
//!   AVX2 and AVX-512 and chosen at run time. They give the same bits at
//!   every level and agree with the general kernels within `f32` rounding
//!   (a vertex sums its springs family by family); about 2× faster on the
//!   lab cloth and 2.5× at 256² (`docs/perf.md`); PBD 2.8× on the lab cloth,
//!   symplectic Euler 1.6–1.7×.
//!   [`solver::StepParams::stencil`] turns them off for comparison.
//! - Memory order: the builders' grids are numbered row by row, so a
//!   spring's two ends are at most a row apart in memory; a mesh read by
//!   [`model::ClothBuilder::from_mesh`] whose vertex order scatters its
//!   edges is renumbered by reverse Cuthill–McKee when that at least halves
//!   the mean distance (a shuffled 101² or 256² grid mesh stepped 2.7–2.9×
//!   slower before; [`model::ClothModel::welded_from`] maps mesh vertices
//!   to cloth vertices, and pins, masses and the mesh write-back follow it).
//! - Parallelism: two cloths or more step in parallel across Bevy's
//!   compute pool (`par_iter_mut`; one cloth steps on the system's thread,
//!   since the pool would only add a thread handoff); a large cloth (at
//!   least [`solver::PARALLEL_MIN`] springs or vertices) splits its loops
//!   in fixed chunks on the same pool when it has more than one thread. On
//!   the stencil kernels a whole step is one parallel region whose passes
//!   are phases of chunks the threads claim in order, not a pool scope per
//!   pass. Results are bitwise the same either way
//!   ([`ClothParams::parallel`] turns it off for a cloth).
//! - The frame: the cloth systems run in [`ClothSchedule`], single-threaded,
//!   from one exclusive system, and the `PostUpdate` pin-following system
//!   runs only when a cloth's entity moved, so one lab cloth adds little
//!   more than its step to Bevy's frame, under either executor (measured in
//!   `docs/perf.md`, "The frame").
//! - `cargo run --release -p bevy_cloth_report -- --perf` writes
//!   `docs/perf.md`: every method from 21² to 256² vertices, 100 cloths in
//!   one app, sparse CG against its parts, the machine's limits, and the
//!   bevy_silk comparison.
//!
//! ## Scheduling
//! - [`ClothPlugins::new`] takes the schedule (default `FixedUpdate`) in
//!   which one exclusive system ([`ClothScheduleSystems`]) runs
//!   [`ClothSchedule`]; [`ClothSystems`] orders the step there (its `First`
//!   and `Last` also order systems of the outer schedule around it);
//!   [`ClothSimulation`] pauses and single-steps every cloth.
//!
//! ## Architecture
//!
//! Three layers, as rapier is to bevy_rapier:
//!
//! - [`model`]: pure data. Topology (springs, vertex→spring adjacency),
//!   masses, pins, state. No systems.
//! - [`solver`] and [`collision`]: pure numerics, a folder per method, each
//!   a settings type implementing [`solver::Method`]: a step takes a model, a
//!   state, parameters and a reusable workspace. No entities, no `Time`, no
//!   `Transform`: testable and benchmarkable alone. The methods share the
//!   engine room (`solver::engine`, hidden from these docs): the SIMD and
//!   grid kernels, the parallel phases and the sparse factorisation, the
//!   only code with `unsafe` (the crate denies it elsewhere).
//! - [`methods`]: the method table, where each method becomes a component,
//!   a plugin and an [`AnyMethod`] variant, and [`PRESETS`]; the generic
//!   [`MethodPlugin`] and the diagnostic for a cloth no method steps.
//! - [`ecs`]: thin glue. Components, system sets and the core plugin that
//!   copy the time step and transforms in, and publish statistics.
//!
//! A cloth's method is a component: inserting [`PbdSolver`] on a cloth that
//! had an [`ImplicitSolver`] removes the latter (one method per cloth) and
//! switches the method at run time. Each method's scratch buffers live in a
//! [`ClothWorkspace`] added and removed with it, so a cloth allocates only
//! what its method needs. Each method plugin's step system runs only while
//! some entity has its component.
//!
//! ### The simulation loop
//!
//! Once per fixed step (the schedule's `Time`), in [`ClothSchedule`], in
//! [`ClothSystems`] order:
//!
//! ```text
//! First:    (user hook)
//! SyncIn:   for each cloth
//!             if new: place rest shape by the entity's global transform
//!             else:   move pinned vertices to transform · rest position
//!           attachments: vertices held by other entities → target · offset · rest
//!                        (the pinned set follows attach/detach; a gone target releases)
//!           ClothSkin: skinned pose from the joints (linear blend skinning); pins → pose
//!           ClothInertia: anchor moved by Δ this step; jump > teleport distance?
//!                         every vertex ← Δ·x, v ← Δ·v (no drag, no guard trip);
//!                         else free x ← x + (1 − s_v)(Δx − x),
//!                              v ← v + s_v(1 − s_a)·(change of the anchor's velocity at x)
//! Forces:   with a Wind resource, for each cloth: per-triangle drag and lift from the
//!           velocity relative to the wind; v ← v + h·F/(m + h·c) (c: drag's damping)
//! Step:     for each cloth, with its method (in parallel across cloths)
//!             keep a copy of the state (last good)
//!             implicit: v ← damping·v; x̃ = x + dt·v; x = x̃
//!                       K times: g = M(x − x̃)/dt² − f(x); x ← x − g/(m/dt² + 4k)
//!                                (Chebyshev: blend with the iterate before last)
//!                       v ← v + (x − x̃)/dt
//!             pbd:      v ← damping·v + dt·g; x ← x + dt·v
//!                       K times: Jacobi strain limiting, v updated with x
//!             symplectic:        v ← damping·v + h·M⁻¹f(x); x ← x + h·v
//!             linear implicit:   fill A = M − h²K, b = M·damping·v + h·f (pattern reused)
//!                                solve A·v⁺ = b (CG warm-started, or LDLᵀ); x ← x + h·v⁺
//!             pd:                x = x̃; up to K times: d_e = L_e(x_a − x_b)/‖x_a − x_b‖ per spring;
//!                                stop if the estimated error (dt²/m·∇Φ, from the right-hand
//!                                sides) is within the tolerance (preset: 1 % of the motion);
//!                                solve (M/h² + Σk AᵀA) x = M/h² x̃ + Mg + Σk Aᵀd (factor
//!                                kept; from 64², one multigrid V-cycle for the correction
//!                                from −∇Φ instead; Chebyshev blend, or Anderson extrapolation
//!                                kept only if Φ drops); v = (x − x₀)/dt
//!             exact:             x = x̃; Newton on Φ(x) = ‖x − x̃‖²_M/2dt² + E(x) with sparse
//!                                Cholesky and line search to ‖∇Φ‖ ≤ 1e-9‖∇Φ(x̃)‖; v = Δx/dt
//!                                (newton: the same to 1e-5, at most 16 iterations)
//!             (penalty spheres, planes, capsules, boxes act inside the step: forces, and stiffness in A; in pd,
//!              projective terms with their stiffness on the matrix's diagonal; projection ones too, and
//!              avian's primitives: projected in stiff's substeps, penalty terms in pd's and newton's objectives;
//!              a ClothSkin's tethers, backstop and max distance: in stiff's substeps, the skin moved
//!              through them from the last step's pose)
//!             guard: state finite, stretch ≤ bound (or shrinking), speed ≤ bound, energy ≤ bound?
//!                    if not: restore last good; retry as 2, 4, … substeps (policy
//!                    Retry) or stop the cloth (policy Pause)
//! Collide:  for each cloth, each projection sphere: move vertices inside to the surface
//!           (Coulomb friction if the sphere has some); then planes, capsules, boxes,
//!           and (feature avian) every avian Collider: out along the contact normal,
//!           then friction takes ≤ μ·(normal impulse) from the tangential velocity
//! SyncOut:  ClothSkin: drive towards the pose, tethers, out of the backstop, within max distance;
//!           for each cloth: no method stepped it? status NoMethod (warn once);
//!           the guard's check again after collision (restore, stop);
//!           send ClothDiverged for each rejected step and ClothNotConverged for
//!           the first unconverged one; record max stretch and energy in ClothStats
//! Last:     (user hook)
//!
//! PostUpdate (every frame, after transform propagation, set ClothFollowSystems):
//!           pinned vertices follow their entity's transform as it is now (not a ClothSkin's)
//! ```
//!
//! When a cloth is inserted, a component hook places its rest shape at its
//! entity's transform at once, so its state is never empty.
//!
//! Pinned vertices are never moved by a solver or a collider. Positions are
//! world-space `f32` (`Vec3A`). A pin's velocity is its displacement since
//! the last step; `stiff` moves the pins along it through its substeps.
//!
//! ## Saving
//! [`Cloth::snapshot`] takes a cloth's dynamic state as a [`ClothSnapshot`]
//! (positions, velocities, where the last step left the pins, the guard's
//! halvings): `Reflect`, and with the `serialize` feature serde's. A game
//! rebuilds the cloth as it built it and calls [`Cloth::restore_snapshot`]:
//! the cloth continues bitwise as if never saved (tested across a new
//! `App`, through JSON); another cloth's snapshot (other vertex count or
//! pins, or a non-finite value) is a typed [`StepError`](solver::StepError)
//! and the cloth keeps its state. A character cloth's [`ClothSkin`] and
//! [`ClothInertia`] remember the last step too (the skin's pose, the
//! anchor's transform and motion): [`CharacterSnapshot`] saves and restores
//! that beside the cloth's snapshot.
//!
//! ## Materials
//! A [`ClothMaterial`](model::ClothMaterial) gives a cloth in physical
//! units: its sheet's stretch stiffness in N/m (the lab's `k = 8000` on its
//! grid is about 12 kN/m) and its areal density in kg/m². Each spring's
//! stiffness (`k = E·A/((3/8)·Σ L²)` per spring kind) and each vertex's
//! mass (a third of its triangles' mass) follow from the mesh, so the same
//! material hangs the same at 16² and at 64². Put it on the cloth entity
//! (it sets [`ClothParams::stiffness`] every step and the masses when the
//! density or the model changes), or use
//! [`ClothBuilder::with_material`](model::ClothBuilder::with_material) and
//! [`ClothMaterial::spring_stiffness`](model::ClothMaterial::spring_stiffness).
//! The lab's per-vertex mass and per-spring `k` stay as they are for
//! fidelity ([`ClothParams::default`] is the lab's).
//!
//! ```
//! use bevy::prelude::*;
//! use bevy_cloth::prelude::*;
//!
//! fn spawn_cape(mut commands: Commands) {
//!     // A 2 m cape, 32×32 vertices, hung by its top edge: 1 kg of cotton.
//!     let model = ClothBuilder::grid(32, 32, Vec3::ZERO, Vec3::X * 2.0, Vec3::NEG_Y * 2.0)
//!         .with_pins(0..32)
//!         .build()
//!         .expect("valid cloth");
//!     let mut cape = commands.spawn((Cloth::new(model), ClothMaterial::COTTON, Transform::default()));
//!     // The default method: `stiff`.
//!     AnyMethod::default().insert(&mut cape);
//! }
//! # let mut app = App::new();
//! # app.add_plugins((MinimalPlugins, ClothPlugins::default())).add_systems(Startup, spawn_cape);
//! # app.update();
//! ```
//!
//! # Frequently Asked Questions
//!
//! **Why does my cloth not move?** It needs a method component and that
//! method's plugin, and the schedule must run: `FixedUpdate` runs once
//! `Time<Fixed>` has accumulated a step. Check [`ClothStats::status`]: a
//! cloth with invalid parameters is `Invalid` (with the typed error), one
//! whose method has no plugin is `NoMethod`. If it is `Running` but hangs in
//! the air, look at [`ClothStats::converged`]: a stiff cloth "locks" when its
//! iterations do not converge.
//!
//! **Where do I move a pinned cloth, or a collider?** Anywhere: pins follow
//! their entity at every fixed step (`SyncIn`) and again after `Update`
//! (`ClothFollowSystems`, in `PostUpdate`), so the frame shows the pins where
//! the entity is. For the physics to see a move in the same fixed step,
//! move it in `FixedUpdate` in [`ClothSystems::First`] (before the whole
//! cloth step), or in [`ClothSchedule`] in the same set.
//!
//! **Which time step?** The schedule's: set `Time::<Fixed>::from_seconds(0.0333)`
//! for the lab's.
//!
//! **My cloth stretches a lot.** Give it a material of real fabric
//! ([`ClothMaterial`](model::ClothMaterial)) and the default method
//! (`stiff`): a cape of 1–2 kg at 16² to 64² and 60 Hz stays within 5 %
//! (tested). For the lab's methods: 32 Jacobi iterations do not converge at
//! `k = 8000`; use Chebyshev, more iterations, or PBD. For stiffer cloth
//! use projective dynamics ([`ProjectiveSolver`], preset `pd`), which stays
//! correct about a decade stiffer than Chebyshev at the same step, or its
//! Anderson-accelerated preset `pd-anderson` for nearly inextensible cloth
//! (see the stability map). Beyond them (k = 1e7–1e8 at long steps), on
//! small cloths, Newton on a budget ([`ExactSolver::BUDGET`], preset
//! `newton`) is right in every hanging and draped cell of the map (45 of
//! 48 falling onto the sphere).
//!
//! **The linearly implicit method stopped with `SolveFailed`, or went
//! wild.** With the assignment's exact spring blocks, compressed springs make
//! `A` indefinite (stiff springs, light particles, large steps): CG then
//! fails and LDLᵀ returns a meaningless solution. Use
//! [`SpringJacobian::ClampCompression`](solver::linear::SpringJacobian).
//!
//! # License
//!
//! MIT OR Apache-2.0.

#![warn(missing_docs)]
#![deny(unsafe_code)]

pub mod aero;
#[cfg(feature = "avian")]
pub mod avian;
pub mod character;
pub mod collision;
#[cfg(feature = "picking")]
pub mod drag;
pub mod ecs;
pub mod methods;
pub mod model;
#[cfg(feature = "render")]
pub mod render;
pub mod solver;
#[cfg(test)]
mod testing;
#[cfg(feature = "egui")]
pub mod ui;

use bevy::app::{PluginGroup, PluginGroupBuilder};
use bevy::ecs::intern::Interned;
use bevy::ecs::schedule::ScheduleLabel;
use bevy::prelude::FixedUpdate;

pub use character::{
    ATTRIBUTE_CLOTH_BACKSTOP, ATTRIBUTE_CLOTH_MAX_DISTANCE, CharacterClothPlugin,
    CharacterSnapshot, ClothInertia, ClothSkin, SkinConstraints, SkinPose, Skinning,
};
pub use collision::{SelfCollision, SelfCollisionError};
pub use ecs::{
    Attachment, CapsuleCollider, Cloth, ClothAerodynamics, ClothAttachments, ClothColliders,
    ClothCorePlugin, ClothDiverged, ClothFollowSystems, ClothFromMesh, ClothGuard, ClothMethods,
    ClothNotConverged, ClothParams, ClothSchedule, ClothScheduleSystems, ClothSimulation,
    ClothSnapshot, ClothStateMut, ClothStats, ClothStatus, ClothSystems, ContactResponse,
    CuboidCollider, DivergenceReason, GuardAction, PlaneCollider, ShapeCollisionPlugin,
    SphereCollider, SphereCollisionPlugin, SphereResponse, Unconverged, Wind, WindPlugin,
};
pub use methods::{
    AnyMethod, ClothMethod, ClothWorkspace, ExactPlugin, ImplicitPlugin, LinearImplicitPlugin,
    MethodPlugin, PRESETS, PbdPlugin, Preset, ProjectivePlugin, SymplecticPlugin, XpbdPlugin,
};
pub use solver::exact::ExactSolver;
pub use solver::implicit::{ImplicitSolver, Rho};
pub use solver::linear::LinearImplicitSolver;
pub use solver::pbd::PbdSolver;
pub use solver::projective::{GlobalSolve, ProjectiveSolver};
pub use solver::symplectic::SymplecticSolver;
pub use solver::xpbd::XpbdSolver;

/// Everything a game needs, in one import.
pub mod prelude {
    pub use crate::ClothPlugins;
    pub use crate::character::{
        ATTRIBUTE_CLOTH_BACKSTOP, ATTRIBUTE_CLOTH_MAX_DISTANCE, CharacterClothPlugin,
        CharacterSnapshot, ClothInertia, ClothSkin, SkinConstraints, SkinPose, Skinning,
    };
    pub use crate::collision::SelfCollision;
    pub use crate::ecs::{
        Attachment, CapsuleCollider, Cloth, ClothAerodynamics, ClothAttachments, ClothCorePlugin,
        ClothDiverged, ClothFollowSystems, ClothFromMesh, ClothGuard, ClothNotConverged,
        ClothParams, ClothSchedule, ClothScheduleSystems, ClothSimulation, ClothSnapshot,
        ClothStats, ClothStatus, ClothSystems, ContactResponse, CuboidCollider, DivergenceReason,
        GuardAction, PlaneCollider, ShapeCollisionPlugin, SphereCollider, SphereCollisionPlugin,
        SphereResponse, Wind, WindPlugin,
    };
    pub use crate::methods::{
        AnyMethod, ExactPlugin, ImplicitPlugin, LinearImplicitPlugin, PRESETS, PbdPlugin,
        ProjectivePlugin, SymplecticPlugin, XpbdPlugin,
    };
    pub use crate::model::{
        ClothBuildError, ClothBuilder, ClothMaterial, ClothModel, ClothState, mesh_vertices_where,
    };
    pub use crate::solver::StepError;
    pub use crate::solver::exact::ExactSolver;
    pub use crate::solver::guard::{GuardBounds, GuardPolicy};
    pub use crate::solver::implicit::{ImplicitSolver, Rho};
    pub use crate::solver::linear::{
        CgConfig, LinearImplicitSolver, LinearSolver, PenaltyJacobian, Preconditioner,
        SpringJacobian,
    };
    pub use crate::solver::pbd::PbdSolver;
    pub use crate::solver::projective::{GlobalSolve, ProjectiveSolver};
    pub use crate::solver::symplectic::SymplecticSolver;
    pub use crate::solver::xpbd::XpbdSolver;
    pub use crate::solver::{Method, ParamError, SpringStiffness, StepParams};
}

/// All cloth plugins.
///
/// | Plugin | Description |
/// |---|---|
/// | [`ClothCorePlugin`] | Components, [`ClothSystems`], placing and pinning cloths, divergence guard. |
/// | [`ImplicitPlugin`] | Steps cloths with an [`ImplicitSolver`] (implicit Euler, Jacobi/Chebyshev). |
/// | [`PbdPlugin`] | Steps cloths with a [`PbdSolver`] (position-based, strain limiting). |
/// | [`SymplecticPlugin`] | Steps cloths with a [`SymplecticSolver`] (symplectic Euler). |
/// | [`LinearImplicitPlugin`] | Steps cloths with a [`LinearImplicitSolver`] (sparse CG or LDLᵀ). |
/// | [`ProjectivePlugin`] | Steps cloths with a [`ProjectiveSolver`] (projective dynamics). |
/// | [`ExactPlugin`] | Steps cloths with an [`ExactSolver`] (Newton to a gradient tolerance: the reference). |
/// | [`XpbdPlugin`] | Steps cloths with an [`XpbdSolver`] (XPBD with small steps: `stiff`). |
/// | [`SphereCollisionPlugin`] | Resolves cloths against [`SphereCollider`]s. |
/// | [`ShapeCollisionPlugin`] | Resolves cloths against [`PlaneCollider`]s (the ground), [`CapsuleCollider`]s and [`CuboidCollider`]s, with friction. |
/// | [`WindPlugin`] | Per-triangle air drag and lift in a gusty [`Wind`], while that resource exists. |
/// | [`CharacterClothPlugin`] | Cloths with a [`ClothSkin`]: skinned to joint entities, pins on the skin, max distance, backstop, anim drive and tethers; cloths with a [`ClothInertia`]: velocity and acceleration scales, teleports. |
/// | `avian::AvianCollisionPlugin` | (feature `avian`) Resolves cloths against the game's avian3d `Collider`s, one-way. |
///
/// Leave out what a scene does not need, either by adding single plugins or
/// by disabling some: `ClothPlugins::default().build().disable::<PbdPlugin>()`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct ClothPlugins {
    schedule: Interned<dyn ScheduleLabel>,
}

impl ClothPlugins {
    /// Runs every cloth system in `schedule` (default `FixedUpdate`).
    pub fn new(schedule: impl ScheduleLabel) -> Self {
        Self {
            schedule: schedule.intern(),
        }
    }
}

impl Default for ClothPlugins {
    fn default() -> Self {
        Self::new(FixedUpdate)
    }
}

impl PluginGroup for ClothPlugins {
    fn build(self) -> PluginGroupBuilder {
        let group = PluginGroupBuilder::start::<Self>().add(ClothCorePlugin::new(self.schedule));
        let group = methods::add_method_plugins(group, self.schedule)
            .add(SphereCollisionPlugin::new(self.schedule))
            .add(ShapeCollisionPlugin::new(self.schedule))
            .add(WindPlugin::new(self.schedule))
            .add(CharacterClothPlugin::new(self.schedule));
        #[cfg(feature = "avian")]
        let group = group.add(avian::AvianCollisionPlugin::new(self.schedule));
        group
    }
}

/// The README's snippets, compiled and run as doctests.
#[cfg(doctest)]
#[doc = include_str!("../README.md")]
struct ReadmeDoctests;
