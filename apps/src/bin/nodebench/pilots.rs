//! Pilots whose future the streamer cannot read: seeded flights that turn, climb and dive, or
//! stop and turn back at random, as a person with W/A/S/D and the mouse does. Their cameras are
//! made ahead (so every run of a seed flies the same path), but the streamer gets them one
//! frame at a time through [`engine::stream::Streamer::update`], which sees only the camera's
//! past (it extrapolates its velocity).

use engine::camera::Camera;
use engine::surface::World;
use glam::{DVec2, DVec3};
use rand::rngs::SmallRng;
use rand::{Rng, SeedableRng};

/// A pilot that hides its future.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Pilot {
    /// Every 2-6 s turns 30-120° to either side at [`TURN_RATE_DEG_S`] (a banked turn, not a
    /// jump of the heading).
    Turning,
    /// Level heading; every 2-6 s a new height over the ground between half the flight's and
    /// 400 m above it, climbed or dived at up to 30° (the pitch changes at most as fast as
    /// [`PITCH_RATE`]); the camera looks along its flight path.
    ClimbingDiving,
    /// Cruises for 2-6 s, brakes to a stop in 0.5 s, hovers 0.5 s, turns round in place in
    /// 1 s and flies back, back at speed after 0.5 s.
    StoppingReversing,
}

/// The heading's turn rate of the turning pilot and of every pilot steering back over the map.
pub(crate) const TURN_RATE_DEG_S: f64 = 60.0;
/// How fast the climbing pilot's vertical speed may change, as a share of the flight's speed
/// per second.
const PITCH_RATE: f64 = 0.5;
/// The largest climb or dive angle's sine (30°).
const MAX_CLIMB_SIN: f64 = 0.5;
/// Share of the map's side along each edge that a pilot turns back from: inside this margin it
/// steers towards the map's centre.
const EDGE_MARGIN: f64 = 0.18;
/// The camera looks this much below its flight path (as the replayed loop does).
const LOOK_DOWN: f64 = 0.25;

impl Pilot {
    pub(crate) const ALL: [Pilot; 3] = [
        Pilot::Turning,
        Pilot::ClimbingDiving,
        Pilot::StoppingReversing,
    ];

    /// Its name on the command line and in rows.
    pub(crate) fn name(self) -> &'static str {
        match self {
            Pilot::Turning => "turning",
            Pilot::ClimbingDiving => "climbing",
            Pilot::StoppingReversing => "reversing",
        }
    }

    pub(crate) fn describe(self) -> String {
        match self {
            Pilot::Turning => {
                format!("turning (30-120° to either side every 2-6 s at {TURN_RATE_DEG_S}°/s)")
            }
            Pilot::ClimbingDiving => {
                "climbing (a new height between half the flight's and 400 m over it every 2-6 s, \
                 at up to 30°)"
                    .to_string()
            }
            Pilot::StoppingReversing => {
                "reversing (stops after 2-6 s, turns round in 1 s, flies back)".to_string()
            }
        }
    }

    pub(crate) fn parse(name: &str) -> Option<Pilot> {
        Pilot::ALL.into_iter().find(|p| p.name() == name)
    }
}

/// Which flights section streaming flies: the replayed loop with its path known, or a pilot
/// that hides its future.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum PilotChoice {
    Known,
    Hidden(Pilot),
}

/// `--pilots` values: `known` or a pilot's name.
pub(crate) fn parse_choice(s: &str) -> Result<PilotChoice, String> {
    if s == "known" {
        return Ok(PilotChoice::Known);
    }
    Pilot::parse(s).map(PilotChoice::Hidden).ok_or_else(|| {
        format!(
            "unknown pilot '{s}': expected known, {}",
            Pilot::ALL.map(Pilot::name).join(", ")
        )
    })
}

/// Where the stopping pilot is in its cycle.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Leg {
    Cruise,
    Brake,
    Hover,
    TurnRound,
    Accelerate,
}

/// Durations of the stopping pilot's legs (s).
const BRAKE_S: f64 = 0.5;
const HOVER_S: f64 = 0.5;
const TURN_ROUND_S: f64 = 1.0;
const ACCELERATE_S: f64 = 0.5;

/// A pilot's state.
struct Flight {
    pos_m: DVec2,
    heading_rad: f64,
    /// The heading being turned to, if any.
    target_heading_rad: Option<f64>,
    speed_m_s: f64,
    /// Height over the ground (or the water) and its rate.
    above_m: f64,
    climb_m_s: f64,
    target_above_m: f64,
    /// When the next manoeuvre starts (s) and the leg it interrupts.
    next_s: f64,
    leg: Leg,
    leg_started_s: f64,
    /// Turn rate of the current turn (rad/s, signed for the turn round).
    turn_round_rad_s: f64,
}

/// The smallest signed angle from `a` to `b` (rad).
fn angle_to(a: f64, b: f64) -> f64 {
    let d = (b - a).rem_euclid(std::f64::consts::TAU);
    if d > std::f64::consts::PI {
        d - std::f64::consts::TAU
    } else {
        d
    }
}

/// The cameras of `pilot`'s flight over `world` at (`speed_m_s`, `above_m` over the ground),
/// `frames` of them `dt_s` apart, from the replayed loop's starting point and heading; `seed`
/// draws its manoeuvres.
pub(crate) fn fly(
    world: &World,
    pilot: Pilot,
    (speed_m_s, above_m): (f64, f64),
    frames: usize,
    dt_s: f64,
    viewport_px: [u32; 2],
    seed: u64,
) -> Vec<Camera> {
    let mut rng = SmallRng::seed_from_u64(seed ^ (pilot as u64).wrapping_mul(0x9e37_79b9));
    let o = DVec2::from(world.origin_m());
    let size = DVec2::from(world.size_m());
    let centre = o + 0.5 * size;
    let inner = (o + EDGE_MARGIN * size, o + (1.0 - EDGE_MARGIN) * size);
    let turn_rate = TURN_RATE_DEG_S.to_radians();
    let ground = |p: DVec2| {
        world
            .height_m(p.x, p.y)
            .max(world.map.manifest.water_level_m)
    };
    let mut f = Flight {
        pos_m: centre + DVec2::new(0.32 * size.x, 0.0),
        heading_rad: std::f64::consts::FRAC_PI_2,
        target_heading_rad: None,
        speed_m_s,
        above_m,
        climb_m_s: 0.0,
        target_above_m: above_m,
        next_s: rng.random_range(2.0..6.0),
        leg: Leg::Cruise,
        leg_started_s: 0.0,
        turn_round_rad_s: 0.0,
    };
    let mut cams = Vec::with_capacity(frames);
    for frame in 0..frames {
        let t = frame as f64 * dt_s;
        let dir = DVec2::new(f.heading_rad.cos(), f.heading_rad.sin());
        let z = ground(f.pos_m) + f.above_m;
        let pos = DVec3::new(f.pos_m.x, f.pos_m.y, z);
        // Looking along the flight path (level flight when hovering), a little below it.
        let horizontal = (f.speed_m_s.powi(2) - f.climb_m_s.powi(2)).max(0.0).sqrt();
        let path = (dir.extend(0.0) * horizontal + DVec3::Z * f.climb_m_s)
            .try_normalize()
            .unwrap_or(dir.extend(0.0));
        let look = (path + DVec3::new(0.0, 0.0, -LOOK_DOWN)).normalize();
        cams.push(Camera::look_at(
            pos,
            pos + look,
            60f64.to_radians(),
            viewport_px,
        ));

        // Manoeuvres start on the clock.
        if t >= f.next_s {
            f.next_s = t + rng.random_range(2.0..6.0);
            match pilot {
                Pilot::Turning => {
                    let side = if rng.random_bool(0.5) { 1.0 } else { -1.0 };
                    let by = rng.random_range(30.0f64..120.0).to_radians();
                    f.target_heading_rad = Some(f.heading_rad + side * by);
                }
                Pilot::ClimbingDiving => {
                    f.target_above_m = rng.random_range(0.5 * above_m..above_m + 400.0);
                }
                Pilot::StoppingReversing => {
                    if f.leg == Leg::Cruise {
                        f.leg = Leg::Brake;
                        f.leg_started_s = t;
                        let side = if rng.random_bool(0.5) { 1.0 } else { -1.0 };
                        f.turn_round_rad_s = side * std::f64::consts::PI / TURN_ROUND_S;
                        f.target_heading_rad = None;
                    }
                }
            }
        }
        // The stopping pilot's legs.
        let in_leg = t - f.leg_started_s;
        let mut steering = true;
        match f.leg {
            Leg::Cruise => {}
            Leg::Brake => {
                steering = false;
                f.speed_m_s = speed_m_s * (1.0 - in_leg / BRAKE_S).max(0.0);
                if in_leg >= BRAKE_S {
                    (f.leg, f.leg_started_s) = (Leg::Hover, t);
                }
            }
            Leg::Hover => {
                steering = false;
                f.speed_m_s = 0.0;
                if in_leg >= HOVER_S {
                    (f.leg, f.leg_started_s) = (Leg::TurnRound, t);
                }
            }
            Leg::TurnRound => {
                steering = false;
                f.heading_rad += f.turn_round_rad_s * dt_s;
                if in_leg + dt_s >= TURN_ROUND_S {
                    (f.leg, f.leg_started_s) = (Leg::Accelerate, t);
                }
            }
            Leg::Accelerate => {
                steering = false;
                f.speed_m_s = speed_m_s * (in_leg / ACCELERATE_S).min(1.0);
                if in_leg >= ACCELERATE_S {
                    (f.leg, f.leg_started_s) = (Leg::Cruise, t);
                    f.next_s = t + rng.random_range(2.0..6.0);
                }
            }
        }
        // Near an edge, heading out: steer back towards the centre (this overrides a drawn
        // turn, at the same rate).
        let p = f.pos_m;
        let outside = p.x < inner.0.x || p.y < inner.0.y || p.x > inner.1.x || p.y > inner.1.y;
        if steering && outside {
            let home = centre - p;
            let home_heading = home.y.atan2(home.x);
            if angle_to(f.heading_rad, home_heading).abs() > 30f64.to_radians() {
                f.target_heading_rad = Some(home_heading);
            }
        }
        if let Some(target) = f.target_heading_rad {
            let left = angle_to(f.heading_rad, target);
            let step = turn_rate * dt_s;
            if left.abs() <= step {
                f.heading_rad = target;
                f.target_heading_rad = None;
            } else {
                f.heading_rad += step.copysign(left);
            }
        }
        // Climb towards the target height, the vertical speed changing smoothly.
        let wanted_climb = (f.target_above_m - f.above_m)
            .clamp(-MAX_CLIMB_SIN * f.speed_m_s, MAX_CLIMB_SIN * f.speed_m_s);
        let dv = PITCH_RATE * speed_m_s * dt_s;
        f.climb_m_s += (wanted_climb - f.climb_m_s).clamp(-dv, dv);
        f.above_m = (f.above_m + f.climb_m_s * dt_s).max(5.0);
        let horizontal = (f.speed_m_s.powi(2) - f.climb_m_s.powi(2)).max(0.0).sqrt();
        let dir = DVec2::new(f.heading_rad.cos(), f.heading_rad.sin());
        f.pos_m += dir * horizontal * dt_s;
    }
    cams
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tiny_world() -> World {
        let map = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../maps/tiny");
        crate::open_world(&map).expect("the committed tiny map opens")
    }

    /// Heading of a camera in plan view (rad).
    fn heading(c: &Camera) -> f64 {
        c.forward.y.atan2(c.forward.x)
    }

    #[test]
    fn pilots_fly_smoothly_over_the_map_and_do_what_they_say() {
        let world = tiny_world();
        let (o, size) = (world.origin_m(), world.size_m());
        let dt = 1.0 / 60.0;
        // 20 m/s over the 512 m map: a 60°/s turn has a 19 m radius, so the pilots stay on it.
        let (speed, above) = (20.0, 10.0);
        let frames = 40 * 60;
        for pilot in Pilot::ALL {
            let cams = fly(&world, pilot, (speed, above), frames, dt, [320, 180], 3);
            assert_eq!(cams.len(), frames);
            assert_eq!(
                cams,
                fly(&world, pilot, (speed, above), frames, dt, [320, 180], 3),
                "{pilot:?}: a seed flies one path"
            );
            let (mut turned_rad, mut stopped, mut lowest, mut highest) =
                (0.0f64, 0usize, f64::MAX, f64::MIN);
            for w in cams.windows(2) {
                let (a, b) = (w[0].position_m, w[1].position_m);
                for p in [a, b] {
                    assert!(
                        (o[0]..=o[0] + size[0]).contains(&p.x)
                            && (o[1]..=o[1] + size[1]).contains(&p.y),
                        "{pilot:?} left the map at {p}"
                    );
                }
                let moved = a.truncate().distance(b.truncate());
                assert!(
                    moved <= speed * dt * 1.000_001,
                    "{pilot:?}: {moved} m in a frame"
                );
                stopped += usize::from(moved == 0.0);
                // Banked turns: the heading never jumps (the turn round in place is the
                // fastest, 180° in 1 s).
                let turn = angle_to(heading(&w[0]), heading(&w[1])).abs();
                let fastest = if pilot == Pilot::StoppingReversing {
                    180.0
                } else {
                    TURN_RATE_DEG_S
                };
                assert!(
                    turn <= fastest.to_radians() * dt * 1.01,
                    "{pilot:?}: turned {:.2}° in a frame",
                    turn.to_degrees()
                );
                turned_rad += turn;
                let over = b.z
                    - world
                        .height_m(b.x, b.y)
                        .max(world.map.manifest.water_level_m);
                (lowest, highest) = (lowest.min(over), highest.max(over));
            }
            // 40 s of manoeuvres every 2-6 s: at least 7 turns of 30° or more, 5 turns round.
            let turned_deg = turned_rad.to_degrees();
            match pilot {
                Pilot::ClimbingDiving => assert!(
                    lowest < above * 1.2 && highest > above + 100.0,
                    "climbs and dives: {lowest:.0}..{highest:.0} m over the ground"
                ),
                Pilot::StoppingReversing => {
                    assert!(stopped >= 2 * 60, "hovers in place: {stopped} still frames");
                    assert!(turned_deg > 5.0 * 180.0, "turned {turned_deg:.0}°");
                }
                Pilot::Turning => {
                    assert!((lowest - above).abs() < 1e-6 && (highest - above).abs() < 1e-6);
                    assert_eq!(stopped, 0);
                    assert!(turned_deg > 7.0 * 30.0, "turned {turned_deg:.0}°");
                }
            }
        }
    }

    #[test]
    fn pilots_parse_by_name() {
        assert_eq!(parse_choice("known"), Ok(PilotChoice::Known));
        for p in Pilot::ALL {
            assert_eq!(parse_choice(p.name()), Ok(PilotChoice::Hidden(p)));
        }
        let err = parse_choice("barrel-roll").unwrap_err();
        assert!(
            err.contains("barrel-roll") && err.contains("turning"),
            "{err}"
        );
    }

    #[test]
    fn signed_angles_take_the_short_way() {
        let d = |a: f64, b: f64| angle_to(a.to_radians(), b.to_radians()).to_degrees();
        assert!((d(10.0, 30.0) - 20.0).abs() < 1e-9);
        assert!((d(350.0, 10.0) - 20.0).abs() < 1e-9);
        assert!((d(10.0, 350.0) + 20.0).abs() < 1e-9);
        assert!((d(0.0, 540.0).abs() - 180.0).abs() < 1e-9);
    }
}
