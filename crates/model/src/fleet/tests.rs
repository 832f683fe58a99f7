//! Fleet plans against the single-robot planner, a from-scratch re-evaluation of every step and
//! a brute-force search over space–time states.

use super::*;
use crate::channel::{C64, expected_gain};
use crate::phases::PhaseMode;
use crate::planner::{PathOptions, Threshold};
use crate::radiomap::{MapKey, build};
use crate::scenario::Scenario;
use std::collections::HashSet;

/// The paper's single-user floor and its continuous gain map.
fn paper_map() -> RadioMap {
    map_of(&Scenario::builtin("paper-single-user").unwrap())
}

/// The free cells of a map (flat indices).
fn free_cells(map: &RadioMap) -> Vec<usize> {
    (0..map.grid.cells())
        .filter(|&c| !map.occupied[c])
        .collect()
}

/// The centre of cell `c` (flat index).
fn centre(map: &RadioMap, c: usize) -> [f64; 2] {
    let (i, j) = map.grid.cell_of(c);
    map.grid.centre(i, j)
}

fn map_of(scenario: &Scenario) -> RadioMap {
    let key = MapKey::gain("x", scenario, PhaseMode::Continuous).unwrap();
    build(scenario, &key, "x".into(), &Default::default()).unwrap()
}

fn options() -> FleetOptions {
    FleetOptions {
        unit: Unit::GainDb,
        v_max_mps: 1.0,
        dt_s: None,
        horizon_s: None,
        access: None,
    }
}

fn models(map: &RadioMap) -> (Vec<std::sync::Arc<crate::channel::ChannelModel>>, f64) {
    match &map.cells {
        CellSolutions::Gain {
            models,
            antenna_height_m,
            ..
        } => (models.clone(), *antenna_height_m),
        CellSolutions::Rate(_) => unreachable!(),
    }
}

/// The field a refused request names.
fn field_of(e: WorkError) -> String {
    match e {
        WorkError::Invalid(e) => e.field,
        WorkError::Cancelled(_) => panic!("cancelled"),
    }
}

/// A robot to plan from `start` to `goal`.
fn trip(start: [f64; 2], goal: [f64; 2], threshold: f64) -> RobotRequest {
    RobotRequest {
        motion: Motion::Trip { start, goal },
        threshold,
    }
}

/// The single-robot grid path at V_max = 1 m/s.
fn single_path(
    map: &RadioMap,
    start: [f64; 2],
    goal: [f64; 2],
    threshold: Threshold,
) -> crate::planner::PathAnswer {
    let options = PathOptions::default();
    crate::planner::plan(map, Unit::GainDb, options, start, goal, threshold, 1.0).unwrap()
}

/// With one robot a surface serves it alone: eq. 12's gain, the map's, at every cell.
#[test]
fn one_robot_gets_the_closed_form_gain() {
    let map = paper_map();
    let (models, height) = models(&map);
    let joint = JointChannel::new(models, height, PhaseMode::Continuous);
    let mut checked = 0;
    for cell in (0..map.grid.cells()).step_by(7) {
        if map.occupied[cell] {
            continue;
        }
        let (i, j) = map.grid.cell_of(cell);
        let link = joint.link(0, map.grid.centre(i, j));
        let config = joint.configure(&[&link], &[1.0]);
        let db = 10.0 * config.gains[0].log10();
        assert!(
            (db - map.values[cell]).abs() < 1e-9,
            "{db} {}",
            map.values[cell]
        );
        checked += 1;
    }
    assert!(checked > 100);
}

/// Two robots the surface reaches: it serves the one further from its requirement, which then
/// gets its best gain while the other gets less than its own best.
#[test]
fn a_surface_serves_the_robot_of_largest_deficit() {
    let map = paper_map();
    let (models, height) = models(&map);
    let joint = JointChannel::new(models, height, PhaseMode::Continuous);
    let (a, b) = (joint.link(0, [-6.0, -8.0]), joint.link(0, [6.0, -8.0]));
    assert!(!a.unreached() && !b.unreached());
    let alone = |l: &Link| joint.configure(&[l], &[1.0]).gains[0];
    let (best_a, best_b) = (alone(&a), alone(&b));
    for (need, expect) in [([best_a, best_b * 0.01], 0), ([best_a * 0.01, best_b], 1)] {
        let config = joint.configure(&[&a, &b], &need);
        assert_eq!(config.served, vec![Some(expect)]);
        let best = [best_a, best_b];
        assert!((config.gains[expect] / best[expect] - 1.0).abs() < 1e-12);
        assert!(config.gains[1 - expect] < best[1 - expect] * 0.99);
    }
}

/// One robot's plan is the single-robot path, cell for cell, with the map's values.
#[test]
fn one_robot_plans_the_single_robot_path() {
    let map = paper_map();
    let (start, goal) = ([-10.0, 0.0], [10.0, 0.0]);
    let threshold = single_path(&map, start, goal, Threshold::Max)
        .threshold
        .unwrap()
        - 1.0;
    let single = single_path(&map, start, goal, Threshold::Value(threshold));
    let plan = plan_fleet(
        &map,
        &[],
        &[trip(start, goal, threshold)],
        options(),
        &Progress::default(),
    )
    .unwrap();
    let robot = &plan.robots[0];
    assert_eq!(robot.planned_by, Some(PlannedBy::Alone));
    let mut cells = robot.cells.clone();
    cells.dedup();
    let expected: Vec<usize> = single
        .waypoints
        .iter()
        .map(|w| map.grid.index(w.i, w.j))
        .collect();
    assert_eq!(cells, expected);
    assert!((robot.distance_m - single.distance_m.unwrap()).abs() < 1e-9);
    assert!(plan.violations.is_empty());
    for instant in &plan.timeline {
        let at = instant.robots[0].unwrap();
        let cell = map.grid.index(at.i, at.j);
        assert!((at.value - map.values[cell]).abs() < 1e-9);
    }
}

/// Cells of the paper floor that are free, spread over it.
fn free_points(map: &RadioMap, count: usize, seed: usize) -> Vec<[f64; 2]> {
    let free = free_cells(map);
    (0..count)
        .map(|k| centre(map, free[(seed + k * 7919) % free.len()]))
        .collect()
}

/// Every step of a plan recomputed from the channel model with the timeline's phases: every
/// served robot meets its requirement, no two share a cell or swap, and the values reported
/// are the ones recomputed.
fn check_from_scratch(map: &RadioMap, robots: &[RobotRequest], plan: &FleetPlan) {
    let (models, height) = models(map);
    for instant in &plan.timeline {
        let theta: Vec<f64> = instant.phases.concat();
        let mut cells = HashSet::new();
        for (r, at) in instant.robots.iter().enumerate() {
            let Some(at) = at else { continue };
            assert!(
                cells.insert((at.i, at.j)),
                "two robots at one cell, step {}",
                instant.step
            );
            let model = &models[at.ap];
            let mut w = vec![C64::new(0.0, 0.0); model.subsurfaces()];
            let direct = model.evaluate([at.x, at.y, height], true, &mut w);
            let db = 10.0 * expected_gain(&direct, &w, &theta).log10();
            assert!((db - at.value).abs() < 1e-9, "{db} against {}", at.value);
            assert!(
                db >= robots[r].threshold - 1e-8,
                "robot {r} at step {}: {db} < {}",
                instant.step,
                robots[r].threshold
            );
        }
    }
    for (a, ra) in plan.robots.iter().enumerate() {
        for (b, rb) in plan.robots.iter().enumerate() {
            if a == b || ra.cells.is_empty() || rb.cells.is_empty() {
                continue;
            }
            let at = |r: &RobotPlan, k: usize| *r.cells.get(k).unwrap_or(r.cells.last().unwrap());
            for k in 0..plan.timeline.len() {
                let swapped = at(ra, k) != at(ra, k + 1)
                    && at(ra, k) == at(rb, k + 1)
                    && at(ra, k + 1) == at(rb, k);
                assert!(!swapped, "robots {a} and {b} swap at step {k}");
            }
        }
    }
}

/// Eight robots on the paper floor, each asking for close to the best its route allows: the
/// plan, re-evaluated from scratch, meets every requirement at every step.
#[test]
fn a_plan_holds_when_every_step_is_recomputed() {
    let map = paper_map();
    let points = free_points(&map, 16, 11);
    let robots: Vec<RobotRequest> = (0..8)
        .map(|r| {
            let (start, goal) = (points[2 * r], points[2 * r + 1]);
            let widest = single_path(&map, start, goal, Threshold::Max);
            trip(start, goal, widest.threshold.unwrap() - 0.5)
        })
        .collect();
    let plan = plan_fleet(&map, &[], &robots, options(), &Progress::default()).unwrap();
    assert!(plan.violations.is_empty(), "{:?}", plan.violations);
    let served = plan.robots.iter().filter(|r| r.unserved.is_none()).count();
    assert!(served >= 6, "only {served} of 8 served");
    check_from_scratch(&map, &robots, &plan);
    assert!(
        plan.robots
            .iter()
            .any(|r| r.planned_by == Some(PlannedBy::SpaceTime) && r.waited_steps > 0)
    );
    // Some surface served a robot other than the first: the robots did share it.
    assert!(plan.timeline.iter().any(|i| {
        i.served
            .iter()
            .any(|s| s.is_some_and(|r| r != Party::Robot(0)))
    }));
}

/// The earliest arrival of robot `r` found by breadth-first search over (cell, step), written
/// apart from the planner: `fixed` holds the routes (cells per step) of the robots before it,
/// `parked` the starts of those after it. Every state is checked from scratch.
#[allow(clippy::too_many_arguments)]
fn brute_force(
    map: &RadioMap,
    robots: &[RobotRequest],
    r: usize,
    fixed: &[(usize, Vec<usize>)],
    parked: &[usize],
    horizon: usize,
) -> Option<usize> {
    let grid = map.grid;
    let (models, height) = models(map);
    let joint = JointChannel::new(models, height, PhaseMode::Continuous);
    let diagonal = |a: usize, b: usize| {
        let (p, q) = (grid.cell_of(a), grid.cell_of(b));
        p.0 != q.0 && p.1 != q.1
    };
    // (cell measured, other cell held) of a fixed route at step k: a step followed by a
    // diagonal neighbour is the inner step of a two-step move.
    let held = |route: &Vec<usize>, k: usize| -> (usize, Option<usize>) {
        let at = |k: usize| *route.get(k).unwrap_or(route.last().unwrap());
        let next = at(k + 1);
        (
            at(k),
            (next != at(k) && diagonal(at(k), next)).then_some(next),
        )
    };
    let end = fixed.iter().map(|(_, c)| c.len() - 1).max().unwrap_or(0);
    let need = |q: usize, ap: usize| {
        10f64.powf(map.links[ap].gain_db_for(Unit::GainDb, robots[q].threshold) / 10.0)
    };
    let ok = |cell: usize, also: Option<usize>, k: usize| {
        let mine = [Some(cell), also];
        let taken = |c: Option<usize>| c.is_some() && mine.contains(&c);
        if parked.iter().any(|&p| taken(Some(p))) {
            return false;
        }
        let mut links = Vec::new();
        let mut needs = Vec::new();
        for (q, route) in fixed {
            let (a, b) = held(route, k);
            if taken(Some(a)) || taken(b) {
                return false;
            }
            let (i, j) = grid.cell_of(a);
            let ap = map.serving_ap(a);
            links.push(joint.link(ap, grid.centre(i, j)));
            needs.push(need(*q, ap));
        }
        let (i, j) = grid.cell_of(cell);
        let ap = map.serving_ap(cell);
        links.push(joint.link(ap, grid.centre(i, j)));
        needs.push(need(r, ap));
        let refs: Vec<&Link> = links.iter().collect();
        let gains = joint.configure(&refs, &needs).gains;
        gains
            .iter()
            .zip(&needs)
            .all(|(g, n)| *g >= n * (1.0 - 1e-9))
    };
    let swaps = |from: usize, to: usize, k: usize| {
        from != to
            && fixed
                .iter()
                .any(|(_, route)| held(route, k).0 == to && held(route, k + 1).0 == from)
    };
    let feasible = |c: usize| !map.occupied[c] && map.values[c] >= robots[r].threshold;
    let cell_of = |[x, y]: [f64; 2]| {
        let (i, j) = grid.snap(x, y).unwrap();
        grid.index(i, j)
    };
    let (start, goal) = robots[r].motion.ends();
    let (start, goal) = (cell_of(start), cell_of(goal));
    if !ok(start, None, 0) {
        return None;
    }
    // Every state reachable at step k, k = 0, 1, …
    let mut layers: Vec<HashSet<usize>> = vec![HashSet::from([start])];
    let mut pending: Vec<(usize, usize, usize)> = Vec::new(); // (arrival step, cell, from)
    for k in 0..=horizon {
        let here: Vec<usize> = layers[k].iter().copied().collect();
        for &c in &here {
            if c == goal && (k + 1..=end + 1).all(|t| ok(goal, None, t)) {
                return Some(k);
            }
        }
        if k == horizon {
            break;
        }
        layers.push(HashSet::new());
        for &(at, c, _) in pending.iter().filter(|p| p.0 == k + 1) {
            layers[k + 1].insert(c);
            let _ = at;
        }
        pending.retain(|p| p.0 != k + 1);
        for &c in &here {
            if ok(c, None, k + 1) {
                layers[k + 1].insert(c);
            }
            let (i, j) = grid.cell_of(c);
            for (di, dj) in [
                (1, 0),
                (-1, 0),
                (0, 1),
                (0, -1),
                (1, 1),
                (1, -1),
                (-1, 1),
                (-1, -1),
            ] {
                let (a, b) = (i as isize + di, j as isize + dj);
                if a < 0 || b < 0 || a >= grid.nx as isize || b >= grid.ny as isize {
                    continue;
                }
                let n = grid.index(a as usize, b as usize);
                let corner = di != 0
                    && dj != 0
                    && (map.occupied[grid.index(a as usize, j)]
                        || map.occupied[grid.index(i, b as usize)]);
                if !feasible(n) || corner {
                    continue;
                }
                let d = if di != 0 && dj != 0 { 2 } else { 1 };
                if k + d > horizon {
                    continue;
                }
                let fine = (1..d).all(|t| ok(c, Some(n), k + t))
                    && ok(n, None, k + d)
                    && (d > 1 || !swaps(c, n, k));
                if !fine {
                    continue;
                }
                if d == 1 {
                    layers[k + 1].insert(n);
                } else {
                    pending.push((k + d, n, c));
                }
            }
        }
    }
    None
}

/// On a 7 × 5 floor, two robots in either priority order with thresholds that make them
/// contend for the surface: whenever the breadth-first search finds a route for a robot given
/// the one before it, the planner serves it, and a route found in space and time arrives as
/// early as the search's.
#[test]
fn the_planner_finds_a_route_whenever_one_exists_within_the_horizon() {
    let map = tiny_map();
    let (free, point) = (free_cells(&map), |c: usize| centre(&map, c));
    let horizon = 16;
    let mut outcomes = std::collections::BTreeMap::new();
    for case in 0..120usize {
        let pick = |k: usize| free[(case * 31 + k * 17 + case * case * 7) % free.len()];
        let (s0, g0, s1, g1) = (pick(0), pick(1), pick(2), pick(3));
        if [s0, g0].contains(&s1) || [s0, g0].contains(&g1) || s0 == g0 {
            continue;
        }
        // Thresholds a little below the weakest end's value: the robots lean on the surface.
        let slack = [0.5, 2.0, 6.0][case % 3];
        let threshold = |s: usize, g: usize| map.values[s].min(map.values[g]) - slack;
        let robots = [
            trip(point(s0), point(g0), threshold(s0, g0)),
            trip(point(s1), point(g1), threshold(s1, g1)),
        ];
        let plan = plan_fleet(
            &map,
            &[],
            &robots,
            FleetOptions {
                horizon_s: Some(horizon as f64),
                ..options()
            },
            &Progress::default(),
        )
        .unwrap();
        assert!(plan.violations.is_empty());
        for r in 0..2 {
            let fixed: Vec<(usize, Vec<usize>)> = (0..r)
                .filter(|&q| plan.robots[q].unserved.is_none())
                .map(|q| (q, plan.robots[q].cells.clone()))
                .collect();
            let parked: Vec<usize> = if r == 0 { vec![s1] } else { vec![] };
            let truth = brute_force(&map, &robots, r, &fixed, &parked, horizon);
            let robot = &plan.robots[r];
            let label = match (robot.planned_by, robot.unserved) {
                (Some(PlannedBy::Alone), _) => "alone",
                (Some(PlannedBy::SpaceTime), _) => "space_time",
                (None, Some(Unserved::Alone { .. })) => "infeasible_alone",
                (None, Some(Unserved::StartConflict)) => "start_conflict",
                (None, Some(Unserved::Horizon { .. })) => "horizon",
                _ => "other",
            };
            *outcomes.entry(label).or_insert(0) += 1;
            match (robot.planned_by, truth) {
                (Some(PlannedBy::SpaceTime), Some(k)) => {
                    assert_eq!(robot.arrival_step, Some(k), "case {case} robot {r}")
                }
                (Some(PlannedBy::Alone), Some(k)) => {
                    assert!(robot.arrival_step.unwrap() >= k, "case {case} robot {r}")
                }
                (Some(PlannedBy::Given), _) => unreachable!("no route is given here"),
                (Some(_), None) => {
                    // Only a route alone may end beyond the horizon.
                    assert_eq!(robot.planned_by, Some(PlannedBy::Alone), "case {case}");
                    assert!(
                        robot.arrival_step.unwrap() > horizon,
                        "case {case} robot {r}"
                    );
                }
                (None, Some(k)) => panic!(
                    "case {case} robot {r}: unserved, but arrives at {k}: {:?}",
                    robot.unserved
                ),
                (None, None) => {}
            }
        }
    }
    eprintln!("{outcomes:?}");
    assert!(
        outcomes.get("space_time").copied().unwrap_or(0) >= 3,
        "{outcomes:?}"
    );
    assert!(
        outcomes.get("horizon").copied().unwrap_or(0)
            + outcomes.get("start_conflict").copied().unwrap_or(0)
            >= 1,
        "{outcomes:?}"
    );
}

/// The small floor at 1 m cells, every robot at 1 m/s.
fn tiny_map() -> RadioMap {
    let scenario = Scenario::builtin_with("small-test", |v| {
        v["grid"]["resolution_m"] = 1.0.into();
        v["mru"]["v_max_mps"] = 1.0.into();
    })
    .unwrap()
    .unwrap();
    map_of(&scenario)
}

/// A route given as poses is driven as given: sampled at every step, reported `given`, and
/// checked, its failures reported as violations rather than planned away.
#[test]
fn a_given_route_is_checked_as_given() {
    let map = paper_map();
    // Along y = 8.5, free from wall to wall, at 0.5 m/s from t = 2 s.
    let poses = vec![[-10.0, 8.5, 2.0], [0.0, 8.5, 22.0], [10.0, 8.5, 42.0]];
    for (threshold, failing) in [(-200.0, false), (100.0, true)] {
        let robots = [RobotRequest {
            motion: Motion::Route(poses.clone()),
            threshold,
        }];
        let plan = plan_fleet(&map, &[], &robots, options(), &Progress::default()).unwrap();
        let robot = &plan.robots[0];
        assert_eq!(robot.planned_by, Some(PlannedBy::Given));
        assert_eq!(robot.arrival_step, Some(84), "42 s in steps of 0.5 s");
        assert!((robot.distance_m - 20.0).abs() < 1e-12);
        let at = |k: usize| plan.timeline[k].robots[0].unwrap();
        // Waiting at its first pose until t = 2 s, then 1 m every 2 s (4 steps).
        assert_eq!(
            (at(0).x, at(4).x, at(8).x, at(12).x),
            (-10.0, -10.0, -9.0, -8.0)
        );
        assert_eq!(at(84).x, 10.0);
        assert_eq!(plan.violations.len(), if failing { 85 } else { 0 });
    }
    let refused = |poses: Vec<[f64; 3]>| {
        let robots = [RobotRequest {
            motion: Motion::Route(poses),
            threshold: 0.0,
        }];
        field_of(plan_fleet(&map, &[], &robots, options(), &Progress::default()).unwrap_err())
    };
    assert_eq!(
        refused(vec![[0.0, 8.5, 1.0], [1.0, 8.5, 1.0]]),
        "robots[0].route[1]"
    );
    assert_eq!(refused(vec![[0.0, 8.5, -1.0]]), "robots[0].route[0]");
    assert_eq!(
        refused(vec![[0.0, 8.5, 0.0], [30.0, 8.5, 5.0]]),
        "robots[0].route[1]"
    );
    assert_eq!(refused(vec![]), "robots[0].route");
    assert_eq!(
        refused(vec![[0.0, 8.5, 0.0], [1.0, 8.5, 1e9]]),
        "robots[0].route"
    );
}

/// Given routes that meet are reported, each pair once with its first step, place and count:
/// against a step-by-step oracle on the sampled poses.
#[test]
fn given_routes_that_meet_are_reported() {
    let map = paper_map();
    let given = |poses: Vec<[f64; 3]>| RobotRequest {
        motion: Motion::Route(poses),
        threshold: -200.0,
    };
    // 0 drives east along y = 0.5 and 1 west along it: they swap or share a cell mid-way.
    // 2 crosses y = 0.5 from south to north at x = 5.5 long after they have passed, then
    // parks at (5.5, 3.5) where 3 arrives later and stays.
    let robots = [
        given(vec![[-4.5, 0.5, 0.0], [4.5, 0.5, 18.0]]),
        given(vec![[4.5, 0.5, 0.0], [-4.5, 0.5, 18.0]]),
        given(vec![[5.5, -3.5, 20.0], [5.5, 3.5, 34.0]]),
        given(vec![[9.5, 3.5, 0.0], [5.5, 3.5, 40.0]]),
    ];
    let plan = plan_fleet(&map, &[], &robots, options(), &Progress::default()).unwrap();
    // The oracle: every pair, every step, from the timeline's positions (a robot stays at its
    // goal once arrived).
    let last = plan.timeline.len() - 1;
    let at = |r: usize, k: usize| {
        let i = &plan.timeline[k.min(last)];
        i.robots[r].map(|p| (p.x, p.y)).unwrap()
    };
    let mut expected = Vec::new();
    for a in 0..robots.len() {
        for b in a + 1..robots.len() {
            let meets: Vec<usize> = (0..=last)
                .filter(|&k| {
                    at(a, k) == at(b, k) || (at(a, k + 1) == at(b, k) && at(b, k + 1) == at(a, k))
                })
                .collect();
            if let Some(&first) = meets.first() {
                expected.push((a, b, first, meets.len()));
            }
        }
    }
    let got: Vec<_> = plan
        .conflicts
        .iter()
        .map(|c| (c.robots[0], c.robots[1], c.step, c.steps))
        .collect();
    assert_eq!(got, expected);
    assert_eq!(
        got.iter().map(|g| (g.0, g.1)).collect::<Vec<_>>(),
        [(0, 1), (2, 3)],
        "the east and west robots meet, and the last two at the parking cell"
    );
    let parking = &plan.conflicts[1];
    assert_eq!((parking.x, parking.y), (5.5, 3.5));
    assert!((parking.time_s - parking.step as f64 * plan.dt_s).abs() < 1e-12);
    // Planned robots never meet anyone: a plan of trips has none.
    let trips = [
        trip([-9.5, 0.5], [9.5, 0.5], -200.0),
        trip([9.5, 0.5], [-9.5, 0.5], -200.0),
    ];
    let plan = plan_fleet(&map, &[], &trips, options(), &Progress::default()).unwrap();
    assert!(plan.conflicts.is_empty());
}

/// A robot planned after a given route never makes it fail where it met its requirement on
/// its own, and never shares its cell; the given route is checked, not moved.
#[test]
fn a_planned_robot_never_breaks_a_given_route() {
    let map = tiny_map();
    let (free, point) = (free_cells(&map), |c: usize| centre(&map, c));
    let (models, height) = models(&map);
    let joint = JointChannel::new(models, height, PhaseMode::Continuous);
    let mut outcomes = std::collections::BTreeMap::new();
    for case in 0..200usize {
        let pick = |k: usize| free[(case * 13 + k * 29 + case * case * 3) % free.len()];
        let (s0, g0, s1, g1) = (pick(0), pick(1), pick(2), pick(3));
        if s0 == g0 || [s0, g0].contains(&s1) || [s0, g0].contains(&g1) {
            continue;
        }
        let t0 = map.values[s0].min(map.values[g0]) - 1.0;
        let path = single_path(&map, point(s0), point(g0), Threshold::Value(t0));
        if !path.feasible {
            continue;
        }
        let poses: Vec<[f64; 3]> = path
            .waypoints
            .iter()
            .map(|w| [w.x, w.y, w.time_s])
            .collect();
        let t1 = map.values[s1].min(map.values[g1]) - [0.5, 3.0][case % 2];
        let robots = [
            RobotRequest {
                motion: Motion::Route(poses),
                threshold: t0,
            },
            trip(point(s1), point(g1), t1),
        ];
        let plan = plan_fleet(&map, &[], &robots, options(), &Progress::default()).unwrap();
        assert_eq!(plan.robots[0].planned_by, Some(PlannedBy::Given));
        *outcomes
            .entry(format!("{:?}", plan.robots[1].planned_by))
            .or_insert(0) += 1;
        if plan.robots[1].unserved.is_some() {
            // Nothing more permissive finds a route either: the breadth-first search holds
            // both cells of a given route's diagonal jump and asks every robot to be met.
            let fixed = [(0, plan.robots[0].cells.clone())];
            let horizon = plan.horizon_steps;
            assert_eq!(
                brute_force(&map, &robots, 1, &fixed, &[], horizon),
                None,
                "case {case}: {:?}",
                plan.robots[1].unserved
            );
        }
        let need = |r: usize, ap: usize| {
            10f64.powf(map.links[ap].gain_db_for(Unit::GainDb, robots[r].threshold) / 10.0)
        };
        for instant in &plan.timeline {
            let a = instant.robots[0].unwrap();
            let alone = joint.link(a.ap, [a.x, a.y]);
            let met_alone =
                joint.configure(&[&alone], &[1.0]).gains[0] >= need(0, a.ap) * (1.0 - 1e-9);
            assert!(
                !met_alone || a.met,
                "case {case}: robot 1 broke the given route at step {}",
                instant.step
            );
            if let Some(b) = instant.robots[1] {
                assert!(
                    b.met,
                    "case {case}: the planned robot fails at step {}",
                    instant.step
                );
                assert_ne!(
                    (a.i, a.j),
                    (b.i, b.j),
                    "case {case}: one cell at step {}",
                    instant.step
                );
            }
        }
    }
    assert!(outcomes.len() >= 2, "{outcomes:?}");
}

/// Four robots sharing the paper floor's one AP by NOMA, then by OMA, each needing a rate:
/// every step recomputed from the channel model with the reported phases, power shares and
/// SIC order gives every served robot at least its rate (eqs. 22 and 24), and the shares of
/// each step fit the AP's power.
#[test]
fn robots_sharing_an_ap_get_their_rates_at_every_step() {
    // The paper's multi-user floor: its static robot (SRU) takes part, needing its rate.
    let scenario = Scenario::builtin("paper-multi-user").unwrap();
    assert_eq!(scenario.srus.len(), 1);
    let map = map_of(&scenario);
    let (models, height) = models(&map);
    let rho = 10f64.powf((map.links[0].offset_dbm - map.links[0].noise_dbm) / 10.0);
    let points = free_points(&map, 8, 5);
    for access in [Access::Noma, Access::Oma] {
        let robots: Vec<RobotRequest> = (0..4)
            .map(|r| {
                let (start, goal) = (points[2 * r], points[2 * r + 1]);
                let options = PathOptions::default();
                let widest = crate::planner::plan(
                    &map,
                    Unit::BpsHz,
                    options,
                    start,
                    goal,
                    Threshold::Max,
                    1.0,
                )
                .unwrap();
                // A fifth of its best rate alone: four robots must share the power.
                trip(start, goal, widest.threshold.unwrap() / 5.0)
            })
            .collect();
        let options = FleetOptions {
            unit: Unit::BpsHz,
            access: Some(access),
            ..options()
        };
        let plan =
            plan_fleet(&map, &scenario.srus, &robots, options, &Progress::default()).unwrap();
        assert!(plan.violations.is_empty(), "{:?}", plan.violations);
        let served = plan.robots.iter().filter(|r| r.unserved.is_none()).count();
        assert!(served >= 3, "{access:?}: {served} served");
        for instant in &plan.timeline {
            let theta = instant.phases.concat();
            // The robots, then the SRU (its requirement after theirs), at its own antenna height.
            let mut present: Vec<(usize, RobotInstant)> = instant
                .robots
                .iter()
                .enumerate()
                .filter_map(|(r, at)| at.map(|a| (r, a)))
                .collect();
            assert_eq!(instant.srus.len(), 1);
            present.push((robots.len(), instant.srus[0]));
            let required = |r: usize| match robots.get(r) {
                Some(robot) => robot.threshold,
                None => scenario.srus[0].min_rate_bps_hz,
            };
            let height_of = |r: usize| match r < robots.len() {
                true => height,
                false => scenario.srus[0].position[2],
            };
            let n = present.len() as f64;
            let gain_at = |r: usize, a: &RobotInstant| {
                let model = &models[a.ap];
                let mut w = vec![C64::new(0.0, 0.0); model.subsurfaces()];
                let direct = model.evaluate([a.x, a.y, height_of(r)], true, &mut w);
                expected_gain(&direct, &w, &theta)
            };
            let total: f64 = present.iter().map(|(_, a)| a.power_share.unwrap()).sum();
            assert!(total <= 1.0 + 1e-9, "step {}: shares {total}", instant.step);
            for (r, a) in &present {
                let (lambda, f) = (gain_at(*r, a), a.power_share.unwrap());
                let rate = match access {
                    Access::Oma => (1.0 + n * lambda * rho * f).log2() / n,
                    Access::Noma => {
                        let place = a.decoded.unwrap();
                        let later: f64 = present
                            .iter()
                            .filter(|(_, b)| b.decoded.unwrap() > place)
                            .map(|(_, b)| b.power_share.unwrap())
                            .sum();
                        (1.0 + lambda * rho * f / (lambda * rho * later + 1.0)).log2()
                    }
                };
                assert!(
                    rate >= required(*r) - 1e-7,
                    "{access:?} step {} party {r}: {rate} < {}",
                    instant.step,
                    required(*r)
                );
                if *r < robots.len() {
                    assert_ne!((a.i, a.j), (instant.srus[0].i, instant.srus[0].j));
                }
                if access == Access::Noma {
                    // SIC decodes the weaker first.
                    for (q, b) in &present {
                        if b.decoded.unwrap() > a.decoded.unwrap() {
                            assert!(gain_at(*q, b) >= lambda * (1.0 - 1e-12));
                        }
                    }
                }
            }
        }
    }
}

/// A robot given to sit on another's straight route for 15 s: the other goes around it (or
/// waits) in space and time, and never shares its cell.
#[test]
fn a_robot_goes_around_a_given_route() {
    let map = paper_map();
    let robots = [
        RobotRequest {
            motion: Motion::Route(vec![[0.0, 9.0, 0.0], [0.0, 9.0, 15.0], [0.0, 8.5, 15.5]]),
            threshold: -200.0,
        },
        trip([-10.0, 9.0], [10.0, 9.0], -200.0),
    ];
    let plan = plan_fleet(&map, &[], &robots, options(), &Progress::default()).unwrap();
    let mover = &plan.robots[1];
    assert_eq!(mover.planned_by, Some(PlannedBy::SpaceTime));
    // The straight row takes 40 steps; around the sitting robot costs a few more, far less
    // than waiting the 30 steps it sits there.
    let arrival = mover.arrival_step.unwrap();
    assert!((41..=46).contains(&arrival), "{arrival}");
    assert!(plan.violations.is_empty());
    check_from_scratch(&map, &robots, &plan);
}

/// A cancelled plan stops with `Cancelled`, before its next robot or within a few thousand
/// states of a search.
#[test]
fn a_cancelled_plan_stops() {
    let map = paper_map();
    let progress = Progress::default();
    progress.cancel();
    let robots = [trip([-10.0, 0.0], [10.0, 0.0], -80.0)];
    assert!(matches!(
        plan_fleet(&map, &[], &robots, options(), &progress),
        Err(WorkError::Cancelled(_))
    ));
    let done = Progress::default();
    let plan = plan_fleet(&map, &[], &robots, options(), &done).unwrap();
    assert_eq!((done.cells_done(), done.cells_total()), (1, 1));
    assert_eq!(plan.robots[0].planned_by, Some(PlannedBy::Alone));
}
