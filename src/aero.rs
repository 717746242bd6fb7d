//! Wind and air: a deterministic gusty wind field and per-triangle
//! aerodynamic drag and lift. Pure numerics, no ECS.
//!
//! # The force on a triangle
//!
//! A triangle of area `A`, unit normal `n` and velocity `v` (the mean of its
//! vertices') moves through air of density `ρ` blowing at `w` (the wind at its
//! centroid): its velocity relative to the air is `u = v − w`. The air pushes
//! it with
//!
//! - **drag** `F_d = −½ρ C_d A |n·u| u`: against the relative motion, in
//!   proportion to the area the triangle shows the flow (`A|n·u|/|u|`);
//! - **lift** `F_l = −½ρ C_l A (|u| (n·u) n − (n·u)² u/|u|)`: across the
//!   relative motion, in the plane of `n` and `u`, of size
//!   `½ρ C_l A |u|² |cos θ| sin θ` (`θ` the angle between `n` and `u`).
//!
//! Both vanish for a triangle edge-on to the flow. Each vertex gets a third
//! of each force of its triangles.
//!
//! # Time integration
//!
//! The forces are explicit external forces of the step: they change each
//! free vertex's velocity before the method runs, which is exactly how every
//! method here treats an external force (it enters `x̃ = x + h·v` for the
//! implicit ones, the velocity update for symplectic Euler and PBD's
//! prediction). Drag alone would then be unstable for a light cloth in a
//! strong flow (`h·c/m > 2`), so its damping part is taken implicitly per
//! vertex: with `c_i` the sum of its triangles' `½ρA|n·u|(C_d + C_l)/3`,
//! `Δv_i = h·F_i/(m_i + h·c_i)`. That is unconditionally stable and never
//! reverses a vertex's motion through the air.

use bevy::math::Vec3A;

use crate::model::{ClothModel, ClothState};

/// How a cloth meets the air: density and coefficients (see the module docs).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AeroCoefficients {
    /// Air density `ρ` (kg/m³; sea level: 1.225).
    pub air_density: f32,
    /// Drag coefficient `C_d` (a flat plate broadside: about 1.2).
    pub drag: f32,
    /// Lift coefficient `C_l`.
    pub lift: f32,
}

impl Default for AeroCoefficients {
    /// Sea-level air, `C_d = 1`, `C_l = 0.5`.
    fn default() -> Self {
        Self {
            air_density: 1.225,
            drag: 1.0,
            lift: 0.5,
        }
    }
}

/// Why wind or air settings were refused.
#[derive(Clone, Copy, Debug, PartialEq, thiserror::Error)]
pub enum AeroError {
    /// A value that must be finite and at least zero is not.
    #[error("{name} must be finite and ≥ 0, got {value}")]
    Negative {
        /// Which value.
        name: &'static str,
        /// What it was.
        value: f32,
    },
    /// The wind's velocity is not finite.
    #[error("the wind's velocity must be finite, got {0:?}")]
    Velocity(Vec3A),
    /// The gust period must be positive.
    #[error("the gust period must be finite and > 0, got {0}")]
    Period(f32),
}

fn non_negative(name: &'static str, value: f32) -> Result<(), AeroError> {
    if value.is_finite() && value >= 0.0 {
        Ok(())
    } else {
        Err(AeroError::Negative { name, value })
    }
}

impl AeroCoefficients {
    /// Checks that every coefficient is finite and at least zero.
    pub fn validate(&self) -> Result<(), AeroError> {
        non_negative("air density", self.air_density)?;
        non_negative("drag coefficient", self.drag)?;
        non_negative("lift coefficient", self.lift)
    }
}

/// A wind field: a mean velocity with deterministic gusts.
///
/// Gusts are a sum of three sines per axis whose frequencies and phases come
/// from `seed`, travelling downwind at the mean speed: the same seed, place
/// and time give the same wind, run after run. `turbulence` scales them: the
/// speed along the wind varies by up to `turbulence` times the mean speed,
/// and across it by up to half that.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WindField {
    /// Mean wind velocity (m/s).
    pub velocity: Vec3A,
    /// Gust strength, a fraction of the mean speed (0: steady wind).
    pub turbulence: f32,
    /// The longest gust's period (s).
    pub gust_period: f32,
    /// Picks the gusts' frequencies and phases.
    pub seed: u64,
}

impl Default for WindField {
    /// Still air.
    fn default() -> Self {
        Self {
            velocity: Vec3A::ZERO,
            turbulence: 0.0,
            gust_period: 2.0,
            seed: 0,
        }
    }
}

/// SplitMix64: the gusts' frequencies and phases from the seed.
fn split_mix(state: &mut u64) -> f32 {
    *state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
    let mut z = *state;
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^= z >> 31;
    (z >> 40) as f32 / (1u64 << 24) as f32
}

impl WindField {
    /// Checks the field: finite velocity, turbulence ≥ 0, period > 0.
    pub fn validate(&self) -> Result<(), AeroError> {
        if !self.velocity.is_finite() {
            return Err(AeroError::Velocity(self.velocity));
        }
        non_negative("turbulence", self.turbulence)?;
        if !(self.gust_period.is_finite() && self.gust_period > 0.0) {
            return Err(AeroError::Period(self.gust_period));
        }
        Ok(())
    }

    /// The wind at `x` and time `t` (s).
    pub fn at(&self, x: Vec3A, t: f64) -> Vec3A {
        let speed_sq = self.velocity.length_squared();
        if self.turbulence == 0.0 || speed_sq == 0.0 {
            return self.velocity;
        }
        let speed = speed_sq.sqrt();
        let along = self.velocity / speed;
        let across = along.any_orthonormal_pair();
        // Gusts travel downwind at the mean speed: phase by the time the
        // air at `x` left the origin's plane.
        let s = t - f64::from(x.dot(along) / speed);
        let mut rng = self.seed;
        let mut gust = [0.0f32; 3];
        for g in &mut gust {
            let mut sum = 0.0;
            for k in 0..3 {
                // Periods 1, ~0.6, ~0.37 of the longest, jittered by the seed.
                let period = f64::from(self.gust_period)
                    * [1.0, 0.61, 0.37][k]
                    * (0.8 + 0.4 * f64::from(split_mix(&mut rng)));
                let phase = std::f64::consts::TAU * f64::from(split_mix(&mut rng));
                sum += (std::f64::consts::TAU * s / period + phase).sin() as f32;
            }
            *g = sum / 3.0;
        }
        let amplitude = self.turbulence * speed;
        self.velocity
            + amplitude * (gust[0] * along + 0.5 * (gust[1] * across.0 + gust[2] * across.1))
    }
}

/// Scratch space for [`apply_air`], reused from step to step.
#[derive(Clone, Debug, Default)]
pub struct AeroWorkspace {
    force: Vec<Vec3A>,
    damping: Vec<f32>,
}

/// The force on one triangle of area `area` and unit normal `normal`
/// moving at `relative` through the air, and its damping coefficient `c`
/// (force ≈ −c·u for small changes of `u`); see the module docs.
#[inline]
pub fn triangle_force(
    relative: Vec3A,
    normal: Vec3A,
    area: f32,
    coefficients: &AeroCoefficients,
) -> (Vec3A, f32) {
    let speed = relative.length();
    if speed == 0.0 {
        return (Vec3A::ZERO, 0.0);
    }
    let q = 0.5 * coefficients.air_density * area;
    let un = normal.dot(relative);
    let drag = -q * coefficients.drag * un.abs() * relative;
    let lift = -q * coefficients.lift * (speed * un * normal - un * un / speed * relative);
    (
        drag + lift,
        q * un.abs() * (coefficients.drag + coefficients.lift),
    )
}

/// Applies one step `dt` of air forces to every free vertex's velocity
/// (see the module docs), with the wind `wind(x)` at triangle centroids.
/// Returns the largest velocity change.
pub fn apply_air(
    model: &ClothModel,
    state: &mut ClothState,
    coefficients: &AeroCoefficients,
    wind: impl Fn(Vec3A) -> Vec3A,
    dt: f32,
    workspace: &mut AeroWorkspace,
) -> f32 {
    let n = state.len();
    workspace.force.clear();
    workspace.force.resize(n, Vec3A::ZERO);
    workspace.damping.clear();
    workspace.damping.resize(n, 0.0);
    let x = &state.positions;
    let v = &state.velocities;
    for t in model.topology().triangles() {
        let [a, b, c] = t.map(|i| i as usize);
        let cross = (x[b] - x[a]).cross(x[c] - x[a]);
        let twice_area = cross.length();
        if twice_area == 0.0 || !twice_area.is_finite() {
            continue;
        }
        let normal = cross / twice_area;
        let centroid = (x[a] + x[b] + x[c]) / 3.0;
        let relative = (v[a] + v[b] + v[c]) / 3.0 - wind(centroid);
        let (force, damping) = triangle_force(relative, normal, 0.5 * twice_area, coefficients);
        for i in [a, b, c] {
            workspace.force[i] += force / 3.0;
            workspace.damping[i] += damping / 3.0;
        }
    }
    let masses = model.masses();
    let pinned = model.pinned();
    let mut largest = 0.0f32;
    for (i, v) in state.velocities.iter_mut().enumerate() {
        if pinned[i] {
            continue;
        }
        let dv = dt * workspace.force[i] / (masses[i] + dt * workspace.damping[i]);
        *v += dv;
        largest = largest.max(dv.length());
    }
    largest
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::ClothBuilder;
    use bevy::math::{Affine3A, Vec3};

    fn close(a: Vec3A, b: Vec3A) -> bool {
        (a - b).length() <= 1e-5 * (1.0 + b.length())
    }

    #[test]
    fn broadside_plate_feels_drag_against_its_motion_and_no_lift() {
        let c = AeroCoefficients::default();
        let (f, damping) = triangle_force(Vec3A::new(0.0, 2.0, 0.0), Vec3A::Y, 3.0, &c);
        // ½ρ C_d A |u|² along −u.
        assert!(
            close(f, Vec3A::new(0.0, -0.5 * 1.225 * 3.0 * 4.0, 0.0)),
            "{f}"
        );
        assert!(damping > 0.0);
    }

    #[test]
    fn edge_on_plate_feels_nothing() {
        let c = AeroCoefficients::default();
        let (f, damping) = triangle_force(Vec3A::new(5.0, 0.0, 1.0), Vec3A::Y, 3.0, &c);
        assert_eq!(f, Vec3A::ZERO);
        assert_eq!(damping, 0.0);
    }

    #[test]
    fn tilted_plate_gets_lift_across_the_flow() {
        // Moving along +x, tilted 30° nose-up (normal leaning back against
        // the motion): lift is perpendicular to the motion, upward.
        let c = AeroCoefficients {
            drag: 0.0,
            ..Default::default()
        };
        let angle = 30f32.to_radians();
        let normal = Vec3A::new(-angle.sin(), angle.cos(), 0.0);
        let u = Vec3A::new(4.0, 0.0, 0.0);
        let (f, _) = triangle_force(u, normal, 1.0, &c);
        assert!(f.dot(u).abs() < 1e-5, "lift is across the flow: {f}");
        // |F| = ½ρ C_l A |u|² |cos θ| sin θ, θ between n and u (120°).
        let theta = normal.angle_between(u);
        let expected = 0.5 * 1.225 * 0.5 * 16.0 * theta.cos().abs() * theta.sin();
        assert!((f.length() - expected).abs() < 1e-4, "{f} vs {expected}");
        assert!(f.y > 0.0, "{f}");
        // The sign of the normal does not matter.
        let (g, _) = triangle_force(u, -normal, 1.0, &c);
        assert!(close(f, g));
    }

    #[test]
    fn strong_drag_never_reverses_a_vertex() {
        // A light sheet falling fast into very dense air: explicit drag
        // would overshoot; the implicit damping never reverses it.
        let model = ClothBuilder::lab_grid(5)
            .with_mass_per_vertex(1e-3)
            .build()
            .unwrap();
        let mut state = ClothState::at_rest(&model, &Affine3A::IDENTITY);
        for v in &mut state.velocities {
            *v = Vec3A::new(0.0, -10.0, 0.0);
        }
        let c = AeroCoefficients {
            air_density: 1000.0,
            ..Default::default()
        };
        let mut ws = AeroWorkspace::default();
        apply_air(&model, &mut state, &c, |_| Vec3A::ZERO, 0.1, &mut ws);
        for v in &state.velocities {
            assert!(v.y < 0.0 && v.y > -10.0, "{v}");
        }
    }

    #[test]
    fn wind_pushes_a_sheet_downwind_and_spares_pins() {
        // A vertical sheet in the x = 0 plane, wind along +x.
        let model = ClothBuilder::grid(
            5,
            5,
            Vec3::ZERO,
            Vec3::new(0.0, 0.0, 1.0),
            Vec3::new(0.0, -1.0, 0.0),
        )
        .with_pins([0])
        .build()
        .unwrap();
        let mut state = ClothState::at_rest(&model, &Affine3A::IDENTITY);
        let mut ws = AeroWorkspace::default();
        let wind = Vec3A::new(8.0, 0.0, 0.0);
        let largest = apply_air(
            &model,
            &mut state,
            &AeroCoefficients::default(),
            |_| wind,
            0.01,
            &mut ws,
        );
        assert!(largest > 0.0);
        assert_eq!(state.velocities[0], Vec3A::ZERO);
        for v in &state.velocities[1..] {
            assert!(v.x > 0.0, "{v}");
            assert!(v.y.abs() < 1e-6 && v.z.abs() < 1e-6, "{v}");
        }
    }

    #[test]
    fn gusts_are_deterministic_bounded_and_seeded() {
        let field = WindField {
            velocity: Vec3A::new(10.0, 0.0, 0.0),
            turbulence: 0.5,
            gust_period: 2.0,
            seed: 7,
        };
        let other = WindField { seed: 8, ..field };
        let mut differs = false;
        for k in 0..200 {
            let t = f64::from(k) * 0.05;
            let x = Vec3A::new(0.3 * k as f32, 1.0, -2.0);
            let w = field.at(x, t);
            assert_eq!(w, field.at(x, t));
            // Along: within ±turbulence·speed; across: within half of it.
            assert!((w.x - 10.0).abs() <= 5.0 + 1e-4, "{w}");
            assert!(w.y.abs() <= 2.5 + 1e-4 && w.z.abs() <= 2.5 + 1e-4, "{w}");
            differs |= other.at(x, t) != w;
        }
        assert!(differs, "the seed picks the gusts");
        let steady = WindField {
            turbulence: 0.0,
            ..field
        };
        assert_eq!(steady.at(Vec3A::ONE, 3.0), field.velocity);
    }

    #[test]
    fn bad_settings_are_typed_errors() {
        let bad = AeroCoefficients {
            drag: -1.0,
            ..Default::default()
        };
        assert!(matches!(
            bad.validate(),
            Err(AeroError::Negative {
                name: "drag coefficient",
                ..
            })
        ));
        let nan = WindField {
            velocity: Vec3A::new(f32::NAN, 0.0, 0.0),
            ..Default::default()
        };
        assert!(matches!(nan.validate(), Err(AeroError::Velocity(_))));
        let period = WindField {
            gust_period: 0.0,
            ..Default::default()
        };
        assert_eq!(period.validate(), Err(AeroError::Period(0.0)));
        assert!(WindField::default().validate().is_ok());
    }
}
