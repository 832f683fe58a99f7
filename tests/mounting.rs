//! Mounting a surface near a point (`mount_within_m`, docs/scenarios.md "Mounting a surface"):
//! the centre lands on the nearest face that faces the way the normal does, the scenario keeps
//! the mounted pose (and its id is that of the pose written out), and what cannot be mounted is
//! refused naming the field. Every mounted scenario passes the same checks as one written by
//! hand, which is the point: the checks are the definition of "hangs on a wall".

use base64::Engine;
use irs_answers::scenario::ScenarioDocument;
use irs_model::input::FieldError;
use irs_model::scenario::Scenario;
use proptest::prelude::*;

/// The small floor (6 × 4 m room, an obstacle 1 × 2 m at (3, 2), 1.5 m tall; AP at (0.5, 3.5))
/// with its IRS (2 sub-surfaces of λ/2 = 74.948 mm: 0.15 m wide) put at `center` facing `normal`, mounted within `within` m.
fn mounted(
    center: [f64; 3],
    normal: [f64; 3],
    within: f64,
    edit: impl FnOnce(&mut serde_json::Value),
) -> Result<Scenario, FieldError> {
    Scenario::builtin_with("small-test", |v| {
        v["irs"]["center"] = serde_json::json!(center);
        v["irs"]["normal"] = serde_json::json!(normal);
        v["irs"]["mount_within_m"] = serde_json::json!(within);
        edit(v);
    })
    .unwrap()
}

/// Half the surface's width: one sub-surface pitch, λ/2 at 2 GHz.
const HALF_WIDTH: f64 = 299_792_458.0 / 2e9 / 2.0;

fn pose(s: &Scenario) -> ([f64; 3], [f64; 3]) {
    let irs = &s.surfaces()[0];
    (irs.center, irs.normal)
}

fn close(a: [f64; 3], b: [f64; 3]) -> bool {
    a.iter().zip(&b).all(|(x, y)| (x - y).abs() < 1e-9)
}

#[test]
fn a_surface_near_a_room_wall_hangs_on_it_and_keeps_only_the_pose() {
    let s = mounted([3.0, 0.3, 2.0], [0.0, 1.0, 0.0], 0.5, |_| {}).unwrap();
    assert_eq!(pose(&s), ([3.0, 0.0, 2.0], [0.0, 1.0, 0.0]));
    // The built-in floor has its IRS at exactly that pose: the same scenario, the same id.
    let written = Scenario::builtin("small-test").unwrap();
    assert_eq!(s.content_hash(), written.content_hash());
    assert!(!s.canonical_json().contains("mount_within_m"));
}

#[test]
fn the_normal_picks_the_face_and_a_corner_keeps_the_surface_whole() {
    // The obstacle's west side (x = 2.5) at 1 m, below its 1.5 m top.
    let s = mounted([2.2, 2.1, 1.0], [-0.8, 0.6, 0.0], 0.5, |_| {}).unwrap();
    let (centre, normal) = pose(&s);
    assert!(close(centre, [2.5, 2.1, 1.0]), "{centre:?}");
    assert_eq!(normal, [-1.0, 0.0, 0.0]);
    // Above the obstacle nothing facing west is within reach.
    let e = mounted([2.2, 2.1, 2.0], [-1.0, 0.0, 0.0], 0.5, |_| {}).unwrap_err();
    assert_eq!(e.field, "irs.mount_within_m");
    // A point south of a 10 cm wall, asking to face north, goes to the wall's north side.
    let wall = |v: &mut serde_json::Value| {
        v["walls"] = serde_json::json!([
            {"from": [1.0, 1.5], "to": [2.0, 1.5], "thickness_m": 0.1, "height_m": 2.5}
        ])
    };
    let s = mounted([1.5, 1.3, 2.0], [0.0, 1.0, 0.0], 0.5, wall).unwrap();
    let (centre, normal) = pose(&s);
    assert!(close(centre, [1.5, 1.55, 2.0]), "{centre:?}");
    assert!(close(normal, [0.0, 1.0, 0.0]), "{normal:?}");
    // Near a corner of the room the surface moves along the wall until all of it is on it.
    let s = mounted([0.01, 0.2, 2.0], [0.0, 1.0, 0.0], 0.5, |_| {}).unwrap();
    assert!(
        close(pose(&s).0, [HALF_WIDTH, 0.0, 2.0]),
        "{:?}",
        pose(&s).0
    );
}

#[test]
fn out_of_range_distances_are_refused() {
    for within in [0.0, -1.0, 5.01] {
        let e = mounted([3.0, 0.3, 2.0], [0.0, 1.0, 0.0], within, |_| {}).unwrap_err();
        assert_eq!(e.field, "irs.mount_within_m", "{within}: {e:?}");
    }
}

/// The small room as a 60 × 40 floor plan at 0.1 m whose `occupied` (column, row from the
/// bottom) pixels are black.
fn with_plan(occupied: impl Fn(usize, usize) -> bool) -> impl FnOnce(&mut serde_json::Value) {
    let mut pgm = b"P5\n60 40\n255\n".to_vec();
    for top_row in 0..40 {
        let row = 39 - top_row;
        pgm.extend((0..60).map(|c| if occupied(c, row) { 0u8 } else { 254 }));
    }
    let image = base64::engine::general_purpose::STANDARD.encode(pgm);
    move |v: &mut serde_json::Value| {
        v["floor_plan"] = serde_json::json!({
            "image": image, "resolution": 0.1, "origin": [0.0, 0.0, 0.0], "negate": 0,
            "occupied_thresh": 0.65, "free_thresh": 0.196,
        });
    }
}

#[test]
fn a_surface_near_scanned_pixels_hangs_on_their_straight_edge() {
    // A block of columns 10–19, rows 10–14 (x 1–2 m, y 1–1.5 m) with a notch at column 14 of
    // its top row: the top edge y = 1.5 runs x 1.0–1.4 and 1.5–2.0.
    let plan =
        with_plan(|c, r| (10..20).contains(&c) && (10..15).contains(&r) && (c, r) != (14, 14));
    let s = mounted([1.38, 1.7, 1.0], [0.0, 1.0, 0.0], 0.5, plan).unwrap();
    let (centre, normal) = pose(&s);
    // On the edge, moved along it so that the surface stops at the notch.
    assert!(close(centre, [1.4 - HALF_WIDTH, 1.5, 1.0]), "{centre:?}");
    assert_eq!(normal, [0.0, 1.0, 0.0]);
    // Typed by hand 1 cm off the edge, the same surface is refused: it floats.
    let plan = with_plan(|c, r| (10..20).contains(&c) && (10..15).contains(&r));
    let e = Scenario::builtin_with("small-test", |v| {
        v["irs"]["center"] = serde_json::json!([1.3, 1.51, 1.0]);
        plan(v);
    })
    .unwrap()
    .unwrap_err();
    assert_eq!(e.field, "irs.center", "{e:?}");
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]

    /// Anywhere on the floor, any direction, obstacles and angled walls about: a mounted
    /// surface passes every check a hand-placed one must (or the mount says why not), moves no
    /// farther than the distance asked plus half its width, and mounting it again changes
    /// nothing.
    #[test]
    fn whatever_is_mounted_passes_the_checks_and_stays_put(
        x in 0.0..6.0f64,
        y in 0.0..4.0f64,
        z in 0.2..2.8f64,
        angle in 0.0..std::f64::consts::TAU,
        // Walls 0.8 m long (and up to 0.3 m thick) kept inside the room and clear of the AP
        // at (0.5, 3.5) and of the SRU at (5.5, 3.5): they end before x = 5.3 + 0.15.
        wall in (1.5..4.5f64, 1.0..3.0f64, 0.0..std::f64::consts::PI, 0.05..0.3f64),
        within in 0.1..2.0f64,
    ) {
        let (wx, wy, wa, wt) = wall;
        let walls = |v: &mut serde_json::Value| {
            v["walls"] = serde_json::json!([{
                "from": [wx, wy], "to": [wx + 0.8 * wa.cos(), wy + 0.8 * wa.sin()],
                "thickness_m": wt, "height_m": 2.5,
            }]);
        };
        let normal = [angle.cos(), angle.sin(), 0.0];
        match mounted([x, y, z], normal, within, walls) {
            Ok(s) => {
                let (centre, n) = pose(&s);
                let moved = (centre[0] - x).hypot(centre[1] - y);
                prop_assert!(moved <= within + HALF_WIDTH + 1e-9, "moved {} m", moved);
                prop_assert_eq!(centre[2], z);
                prop_assert!(n[0] * normal[0] + n[1] * normal[1] > 0.0);
                let (c2, n2) = pose(&mounted(centre, n, within, walls).unwrap());
                prop_assert!(close(c2, centre) && close(n2, n), "{:?} {:?} → {:?} {:?}", centre, n, c2, n2);
            }
            // Refused: by the mount (nothing near) or by a check of the mounted surface (the
            // AP behind it, the surface past the ceiling): never by a crash.
            Err(e) => prop_assert!(e.field.starts_with("irs."), "{:?}", e),
        }
    }
}
