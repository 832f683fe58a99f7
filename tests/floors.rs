//! Floors given as pixels and as walls give the maps their boxes give (docs/scenarios.md
//! "Floor plans"): the paper floor drawn as a 0.05 m raster and as walls, cell by cell.

mod common;

use base64::Engine;
use common::gain_map;
use irs_answers::scenario::ScenarioDocument;
use irs_model::floorplan::MapMode;
use irs_model::phases::PhaseMode;
use irs_model::planner::{self, Threshold};
use irs_model::radiomap::RadioMap;
use irs_model::scenario::Scenario;

/// The paper floor with its five boxes replaced by a floor plan: 400 × 400 pixels of 0.05 m
/// from (−10, −10), a pixel occupied where its centre lies in a box, 1.3 m high.
fn paper_as_raster() -> Scenario {
    let boxes = Scenario::builtin("paper-single-user")
        .unwrap()
        .obstructions();
    let (side, res) = (400usize, 0.05);
    let mut values = vec![0i8; side * side];
    for r in 0..side {
        for c in 0..side {
            let (x, y) = (
                -10.0 + (c as f64 + 0.5) * res,
                -10.0 + (r as f64 + 0.5) * res,
            );
            if boxes.covers(x, y) {
                values[r * side + c] = 100;
            }
        }
    }
    let map = irs_answers::mapfile::encode_map(
        &values,
        side,
        res,
        [-10.0, -10.0],
        MapMode::Trinary,
        "p.pgm",
    );
    Scenario::builtin_with("paper-single-user", |v| {
        v["obstacles"] = serde_json::json!([]);
        v["floor_plan"] = serde_json::json!({
            "image": base64::engine::general_purpose::STANDARD.encode(&map.pgm),
            "resolution": res, "origin": [-10.0, -10.0, 0.0], "negate": 0,
            "occupied_thresh": 0.65, "free_thresh": 0.25, "obstacle_height_m": 1.3,
        });
    })
    .unwrap()
    .unwrap()
}

fn assert_same_map(a: &RadioMap, b: &RadioMap, what: &str) {
    assert_eq!(a.occupied, b.occupied, "{what}: occupied cells");
    let mut worst = 0.0f64;
    for (k, (x, y)) in a.values.iter().zip(&b.values).enumerate() {
        assert_eq!(x.is_nan(), y.is_nan(), "{what}: cell {k}");
        if x.is_finite() {
            worst = worst.max((x - y).abs());
        }
    }
    assert!(worst <= 1e-9, "{what}: largest difference {worst:e} dB");
}

/// Every cell of the raster floor equals the box floor to 1e-9 dB, in the continuous and the
/// no-IRS maps, and the largest threshold from q_I to q_F stays −59.60 dB.
#[test]
fn the_paper_floor_as_pixels_gives_the_box_map() {
    let boxes = Scenario::builtin("paper-single-user").unwrap();
    let raster = paper_as_raster();
    assert_ne!(boxes.content_hash(), raster.content_hash());
    for phases in [PhaseMode::Continuous, PhaseMode::None] {
        let (a, b) = (gain_map(&boxes, phases), gain_map(&raster, phases));
        assert_same_map(&a, &b, &format!("{phases:?}"));
    }
    let map = gain_map(&raster, PhaseMode::Continuous);
    let path = planner::plan(
        &map,
        map.native_unit(),
        Default::default(),
        [-10.0, 0.0],
        [10.0, 0.0],
        Threshold::Max,
        1.0,
    )
    .unwrap();
    let max = path.max_feasible_threshold.unwrap();
    assert!((max - -59.60).abs() < 0.005, "{max}");
}

/// The five boxes written as walls (one per box, along its x axis, as thick as the box is deep)
/// give the box map: an axis-aligned wall is a box.
#[test]
fn the_paper_floor_as_walls_gives_the_box_map() {
    let boxes = Scenario::builtin("paper-single-user").unwrap();
    let walls = Scenario::builtin_with("paper-single-user", |v| {
        let walls: Vec<serde_json::Value> = v["obstacles"]
            .as_array()
            .unwrap()
            .iter()
            .map(|o| {
                let (cx, cy) = (
                    o["center"][0].as_f64().unwrap(),
                    o["center"][1].as_f64().unwrap(),
                );
                let (sx, sy) = (
                    o["size"][0].as_f64().unwrap(),
                    o["size"][1].as_f64().unwrap(),
                );
                serde_json::json!({
                    "from": [cx - sx / 2.0, cy], "to": [cx + sx / 2.0, cy],
                    "thickness_m": sy, "height_m": o["height_m"],
                })
            })
            .collect();
        v["obstacles"] = serde_json::json!([]);
        v["walls"] = walls.into();
    })
    .unwrap()
    .unwrap();
    assert_same_map(
        &gain_map(&boxes, PhaseMode::Continuous),
        &gain_map(&walls, PhaseMode::Continuous),
        "walls",
    );
}

/// A wall at 45° casts a shadow: cells behind it lose the direct link, cells beside it keep it.
#[test]
fn a_diagonal_wall_shadows_the_cells_behind_it() {
    let s = Scenario::builtin_with("paper-single-user", |v| {
        v["obstacles"] = serde_json::json!([]);
        v["walls"] = serde_json::json!([
            {"from": [-3.0, 3.0], "to": [3.0, -3.0], "thickness_m": 0.2, "height_m": 3.0}
        ]);
    })
    .unwrap()
    .unwrap();
    let model = irs_model::channel::ChannelModel::new(&s);
    let ap = s.ap().position;
    // The AP at (0, 10, 2): (−3, −3) sees it past the wall's end; (−1, −1) is behind it.
    assert!(model.is_blocked(ap, [-1.0, -1.0, 1.0]));
    assert!(!model.is_blocked(ap, [-6.0, -3.0, 1.0]));
    let map = gain_map(&s, PhaseMode::None);
    let g = map.grid;
    let cell = |x: f64, y: f64| {
        let (i, j) = g.snap(x, y).unwrap();
        g.index(i, j)
    };
    assert!(map.occupied[cell(0.0, 0.0)] && !map.occupied[cell(1.0, 0.0)]);
    // Against the open floor: the shadowed cell loses the LoS path loss advantage (2.4 dB at
    // 11 m, 3GPP InF-SH), the cell past the wall's end loses nothing.
    let open = gain_map(
        &Scenario::builtin_with("paper-single-user", |v| {
            v["obstacles"] = serde_json::json!([])
        })
        .unwrap()
        .unwrap(),
        PhaseMode::None,
    );
    let (behind, past) = (cell(-1.0, -1.0), cell(-6.0, -3.0));
    assert!(map.values[behind] < open.values[behind] - 2.0);
    assert_eq!(map.values[past], open.values[past]);
}

/// Nav2's depot map (tests/data/nav2-depot, a scan the project did not draw) at a 0.25 m grid:
/// its thin walls cross many cells away from their centres. No move of the planner's graph
/// between free cells crosses an occupied pixel (the exact segment test), where the rule of
/// occupied centres let many through; and a path across the depot keeps off every pixel.
#[test]
fn no_move_crosses_a_wall_of_a_public_ros_map() {
    let file =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/nav2-depot/depot.json");
    let depot = Scenario::from_file(&file).expect("the depot scenario");
    let map = gain_map(&depot, PhaseMode::None);
    let grid = depot.grid();
    let obstructions = depot.obstructions();
    let at = |i: usize, j: usize, z: f64| {
        let [x, y] = grid.centre(i, j);
        [x, y, z]
    };
    let (mut moves, mut crossing_before) = (0, 0);
    for i in 0..grid.nx {
        for j in 0..grid.ny {
            for (di, dj) in [(1i64, 0i64), (0, 1), (1, 1), (1, -1)] {
                let (k, l) = (i as i64 + di, j as i64 + dj);
                if k >= grid.nx as i64 || l < 0 || l >= grid.ny as i64 {
                    continue;
                }
                let (k, l) = (k as usize, l as usize);
                let (a, b) = (at(i, j, 0.5), at(k, l, 0.5));
                let centre_free = |p: [f64; 3]| !obstructions.covers(p[0], p[1]);
                if centre_free(a) && centre_free(b) && obstructions.blocks(a, b) {
                    crossing_before += 1;
                }
                if map.occupied[grid.index(i, j)] || map.occupied[grid.index(k, l)] {
                    continue;
                }
                moves += 1;
                assert!(!obstructions.blocks(a, b), "{a:?} → {b:?} crosses a wall");
            }
        }
    }
    assert!(moves > 10_000, "{moves} free moves");
    // The map does exercise the rule: with only centres tested, moves went through walls.
    assert!(
        crossing_before > 10,
        "{crossing_before} moves crossed walls before"
    );
    let path = planner::plan(
        &map,
        map.native_unit(),
        Default::default(),
        [1.0, 1.0],
        [29.0, 14.0],
        Threshold::Max,
        1.0,
    );
    if let Ok(path) = path {
        for pair in path.waypoints.windows(2) {
            let ([ax, ay], [bx, by]) = ([pair[0].x, pair[0].y], [pair[1].x, pair[1].y]);
            assert!(
                !obstructions.blocks([ax, ay, 0.5], [bx, by, 0.5]),
                "the path crosses a wall"
            );
        }
    }
    // Any-angle segments are long: none crosses a wall either, and the route is shorter.
    let threshold = Threshold::Value(f64::NEG_INFINITY);
    let (from, to) = ([1.0, 1.0], [29.0, 14.0]);
    let any = planner::plan(
        &map,
        map.native_unit(),
        irs_model::planner::PathOptions::any_angle(),
        from,
        to,
        threshold,
        1.0,
    )
    .unwrap();
    let grid_path = planner::plan(
        &map,
        map.native_unit(),
        Default::default(),
        from,
        to,
        threshold,
        1.0,
    )
    .unwrap();
    assert_eq!(any.feasible, grid_path.feasible);
    if any.feasible {
        let (a, g) = (any.distance_m.unwrap(), grid_path.distance_m.unwrap());
        eprintln!(
            "depot: any-angle {a:.2} m vs grid {g:.2} m, {} vertices",
            any.vertices.len()
        );
        assert!(a <= g + 1e-9);
        for pair in any.vertices.windows(2) {
            let (p, q) = (&any.waypoints[pair[0]], &any.waypoints[pair[1]]);
            assert!(
                !obstructions.blocks([p.x, p.y, 0.5], [q.x, q.y, 0.5]),
                "an any-angle segment crosses a wall"
            );
        }
    }
    // Where the 0.25 m grid closes a gap the robot could drive through, the map says so.
    let passages = &map.closed_passages;
    eprintln!(
        "depot at 0.25 m: {} closed passages, largest {:?}",
        passages.total,
        passages.listed.first()
    );
    assert_eq!(map.stats().closed_passages, passages.total);
    for p in &passages.listed {
        assert!(p.joins >= 2 && p.cells >= 1);
    }
}

/// A robot's radius widens the occupied region (Nav2's inflation): on the depot, a 0.3 m robot
/// keeps off more cells, and none of its moves passes within 0.3 m of a wall in x and y; a
/// radius of 0 written out is the scenario without it (the same id).
#[test]
fn a_robots_radius_keeps_it_off_the_walls() {
    let file =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/nav2-depot/depot.json");
    let text = std::fs::read_to_string(&file).unwrap();
    let mut doc: serde_json::Value = serde_json::from_str(&text).unwrap();
    let base = file.parent().unwrap();
    let with = |doc: &serde_json::Value| {
        Scenario::from_value_with_files(doc.clone(), base).expect("a valid depot variant")
    };
    let plain = with(&doc);
    doc["mru"]["radius_m"] = 0.0.into();
    assert_eq!(
        with(&doc).content_hash(),
        plain.content_hash(),
        "radius 0 is the default"
    );
    doc["mru"]["radius_m"] = 0.3.into();
    let wide = with(&doc);
    assert_ne!(wide.content_hash(), plain.content_hash());
    let (narrow_map, wide_map) = (
        gain_map(&plain, PhaseMode::None),
        gain_map(&wide, PhaseMode::None),
    );
    let count = |m: &RadioMap| m.occupied.iter().filter(|o| **o).count();
    assert!(
        count(&wide_map) > count(&narrow_map) + 100,
        "{} vs {}",
        count(&wide_map),
        count(&narrow_map)
    );
    for (k, (&w, &n)) in wide_map
        .occupied
        .iter()
        .zip(&narrow_map.occupied)
        .enumerate()
    {
        assert!(w || !n, "cell {k} is free only with the radius");
    }
    doc["mru"]["radius_m"] = (-0.1).into();
    let refused = Scenario::from_value_with_files(doc.clone(), base).unwrap_err();
    assert_eq!(refused.field, "mru.radius_m");
}
