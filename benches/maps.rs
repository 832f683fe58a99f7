//! Speed targets (README "Performance"): gain maps of the paper scenario in both groupings,
//! a 1001 × 1001 gain map and A* on it, the full NOMA rate map with certificate, the per-cell
//! cost of the `fast` solver and of the certificate, and the warehouse floor plan (decode +
//! gain map at 0.25 m and 0.1 m, a path query on it), a factory hall with 40 machines, and a
//! path answer on the paper map as the service writes it, and route graphs on the warehouse
//! (scoring ~10 000 edges, a route query at 10 000 nodes).
//!
//! `cargo bench` runs everything; `cargo bench -- gain` a subset. Single-core figures come from
//! `RAYON_NUM_THREADS=1 cargo bench`.

use criterion::{Criterion, criterion_group, criterion_main};
use irs_answers::path::{CheckedPath, write_phases};
use irs_answers::phase_text::{PhaseFormat, PhasePrecision};
use irs_answers::scenario::ScenarioDocument;
use irs_model::channel::ChannelModel;
use irs_model::phases::PhaseMode;
use irs_model::planner::{self, CellGraph, Threshold, route_graph};
use irs_model::radiomap::{MapKey, Progress};
use irs_model::rate::{Access, RateModel};
use irs_model::scenario::Scenario;
use irs_model::scenario::route_graph::{
    GraphEdge, GraphFormat, GraphNode, GraphSource, RouteGraph,
};
use irs_model::solver::{self, certificate, fast};
use std::hint::black_box;
use std::time::Duration;

fn paper(name: &str, edit: impl FnOnce(&mut serde_json::Value)) -> Scenario {
    Scenario::builtin_with(name, edit).unwrap().unwrap()
}

fn gain_maps(c: &mut Criterion) {
    for grouping in ["coherent", "elements"] {
        let s = paper("paper-single-user", |v| {
            v["irs"]["grouping"] = grouping.into();
        });
        let key = MapKey::gain("bench", &s, PhaseMode::Continuous).unwrap();
        c.bench_function(&format!("gain_map_41x41_{grouping}"), |b| {
            b.iter(|| irs_answers::map::build(black_box(&s), &key, &Progress::default()).unwrap())
        });
    }
}

fn large_grid(c: &mut Criterion) {
    // The paper floor at 2 cm resolution: 1001 × 1001 cells, M = 1200 coherent.
    let s = paper("paper-single-user", |v| {
        v["grid"]["resolution_m"] = 0.02.into();
    });
    let key = MapKey::gain("bench", &s, PhaseMode::Continuous).unwrap();
    let mut group = c.benchmark_group("large");
    group
        .sample_size(10)
        .measurement_time(Duration::from_secs(20));
    group.bench_function("gain_map_1001x1001", |b| {
        b.iter(|| irs_answers::map::build(black_box(&s), &key, &Progress::default()).unwrap())
    });
    let map = irs_answers::map::build(&s, &key, &Progress::default()).unwrap();
    let graph = CellGraph {
        grid: &map.grid,
        values: &map.values,
        occupied: &map.occupied,
    };
    let start = map.grid.index(0, 500);
    let goal = map.grid.index(1000, 500);
    // At −62 dB the path is nearly straight; just below the largest feasible threshold the
    // feasible region is a thin web and the search explores much of the floor.
    let widest = graph.widest_path_threshold(start, goal).unwrap();
    for (name, threshold) in [
        ("astar_1001x1001_at_minus_62_db", -62.0),
        ("astar_1001x1001_near_max_threshold", widest - 0.05),
    ] {
        assert!(graph.a_star_path(start, goal, threshold).is_ok());
        group.bench_function(name, |b| {
            b.iter(|| graph.a_star_path(start, goal, black_box(threshold)))
        });
    }
    group.bench_function("widest_path_1001x1001", |b| {
        b.iter(|| graph.widest_path_threshold(start, goal))
    });
    // The same searches the other way, and a one-step query (widest path + grid path, by
    // `planner::plan`, which keeps no index) both ways: the cost must not depend on the
    // direction.
    group.bench_function("astar_1001x1001_at_minus_62_db_reversed", |b| {
        b.iter(|| graph.a_star_path(goal, start, black_box(-62.0)))
    });
    group.bench_function("widest_path_1001x1001_reversed", |b| {
        b.iter(|| graph.widest_path_threshold(goal, start))
    });
    // The widest-path index the service keeps per map: its build, and a query on it.
    group.bench_function("bottleneck_index_build_1001x1001", |b| {
        b.iter(|| planner::Bottlenecks::new(black_box(&graph)))
    });
    let index = planner::Bottlenecks::new(&graph);
    assert_eq!(
        index.widest_path_threshold(&map.values, start, goal),
        Some(widest)
    );
    group.bench_function("widest_path_1001x1001_indexed", |b| {
        b.iter(|| index.widest_path_threshold(&map.values, black_box(start), goal))
    });
    // Random distinct queries (start, goal and threshold), as a fleet asks them: ends drawn
    // among the free cells, the threshold up to 10 dB below the pair's widest path, so every
    // query has a path. A* and the jump point search answer the same list with the same
    // lengths; the time is for the whole list of 64.
    let jumps = planner::JumpIndex::new(&graph);
    let queries = random_queries(&map, &index, 64);
    for &(s, g, t) in &queries {
        let (a, b) = (
            graph.a_star_path(s, g, t).unwrap(),
            jumps.shortest_path(&graph, s, g, t).unwrap(),
        );
        assert_eq!(a.distance_m, b.distance_m);
    }
    group.bench_function("random_64_queries_astar", |b| {
        b.iter(|| {
            for &(s, g, t) in &queries {
                black_box(graph.a_star_path(s, g, t).unwrap());
            }
        })
    });
    group.bench_function("random_64_queries_jump_points", |b| {
        b.iter(|| {
            for &(s, g, t) in &queries {
                black_box(jumps.shortest_path(&graph, s, g, t).unwrap());
            }
        })
    });
    group.bench_function("jump_index_build_1001x1001", |b| {
        b.iter(|| {
            let index = planner::JumpIndex::new(black_box(&graph));
            index.fill(&graph);
            index
        })
    });
    let centre = |cell: usize| {
        let (i, j) = map.grid.cell_of(cell);
        map.grid.centre(i, j)
    };
    let (here, next) = (map.grid.index(500, 700), map.grid.index(501, 700));
    for (name, from, to) in [
        ("one_step_query_forward", here, next),
        ("one_step_query_backward", next, here),
    ] {
        group.bench_function(name, |b| {
            b.iter(|| {
                planner::plan(
                    &map,
                    map.native_unit(),
                    Default::default(),
                    centre(from),
                    centre(to),
                    Threshold::Max,
                    1.0,
                )
            })
        });
    }
    group.finish();
}

/// `count` feasible queries (start, goal, threshold) on `map`, drawn from a fixed seed: ends
/// among the free cells with a value, the threshold uniform in the 10 dB below the pair's
/// widest path.
fn random_queries(
    map: &irs_model::radiomap::RadioMap,
    index: &planner::Bottlenecks,
    count: usize,
) -> Vec<(usize, usize, f64)> {
    use rand::{RngExt, SeedableRng};
    let mut rng = rand::rngs::StdRng::seed_from_u64(0x853C_49E6_748F_EA9B);
    let mut next = move || rng.random::<u64>();
    let free: Vec<usize> = (0..map.values.len())
        .filter(|&c| !map.occupied[c] && map.values[c].is_finite())
        .collect();
    let mut queries = Vec::with_capacity(count);
    while queries.len() < count {
        let s = free[next() as usize % free.len()];
        let g = free[next() as usize % free.len()];
        if let Some(widest) = index.widest_path_threshold(&map.values, s, g) {
            let below = (next() % 1_000_000) as f64 * 1e-5;
            queries.push((s, g, widest - below));
        }
    }
    queries
}

fn rate_maps(c: &mut Criterion) {
    let s = paper("paper-multi-user", |_| {});
    let mut group = c.benchmark_group("rate");
    group
        .sample_size(10)
        .measurement_time(Duration::from_secs(30));
    let key = MapKey::rate("bench", &s, PhaseMode::Continuous, Access::Noma).unwrap();
    group.bench_function("noma_map_41x41_n60_fast_with_certificate", |b| {
        b.iter(|| irs_answers::map::build(black_box(&s), &key, &Progress::default()).unwrap())
    });
    group.finish();

    // Per cell, at a cell behind the central obstacle: the paper's surface (N = 60) and a
    // 16 × 16 one of 4 elements each (N = 256, M = 1024).
    let mut group = c.benchmark_group("rate_cell");
    for (n, edit) in [(60, None), (256, Some((16, 16, 4)))] {
        let s = paper("paper-multi-user", |v| {
            if let Some((nx, nz, per_sub)) = edit {
                v["irs"]["nx_sub"] = nx.into();
                v["irs"]["nz_sub"] = nz.into();
                v["irs"]["elements_per_sub"] = per_sub.into();
            }
        });
        let channel = ChannelModel::new(&s);
        let srus = solver::sru_part(&channel, &s, true);
        let problem = solver::cell_problem(&channel, [3.0, -6.0, 1.0], &srus, true);
        let model = RateModel::for_scenario(&s, Access::Noma);
        group.bench_function(format!("fast_n{n}"), |b| {
            b.iter(|| fast::solve(black_box(&problem), &model))
        });
        group.bench_function(format!("certificate_n{n}"), |b| {
            b.iter(|| certificate::certify(black_box(&problem), &model, None).upper_bound)
        });
    }
    // Three SRUs: the joint dual per decoding order, from the primal's phases as a map does.
    let s = paper("paper-multi-user", |v| {
        let list = v["srus"].as_array_mut().unwrap();
        for p in [[-8.0, -8.0, 1.3], [8.0, -8.0, 1.3]] {
            list.push(serde_json::json!({"position": p, "min_rate_bps_hz": 0.5}));
        }
    });
    let channel = ChannelModel::new(&s);
    let srus = solver::sru_part(&channel, &s, true);
    let problem = solver::cell_problem(&channel, [3.0, -6.0, 1.0], &srus, true);
    let model = RateModel::for_scenario(&s, Access::Noma);
    let hint = fast::solve(&problem, &model);
    group.bench_function("fast_k3_n60", |b| {
        b.iter(|| fast::solve(black_box(&problem), &model))
    });
    group.bench_function("certificate_k3_n60", |b| {
        b.iter(|| certificate::certify(black_box(&problem), &model, Some(&hint)).upper_bound)
    });
    group.finish();
}

/// The warehouse scenario document with its floor plan read and inlined, at `resolution_m`.
fn warehouse_document(resolution_m: f64) -> serde_json::Value {
    let path =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("scenarios/warehouse/warehouse.json");
    let mut document: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
    document["grid"]["resolution_m"] = resolution_m.into();
    let folder = path.parent().unwrap();
    irs_answers::mapfile::resolve_map_reference(
        &mut document,
        folder,
        &irs_answers::files::read_regular,
    )
    .unwrap();
    irs_answers::route_graph::resolve_graph_reference(
        &mut document,
        folder,
        &irs_answers::files::read_regular,
    )
    .unwrap();
    document
}

fn floors(c: &mut Criterion) {
    let mut group = c.benchmark_group("warehouse");
    group.sample_size(10);
    // From the inline document (base64 PGM, 1200 × 800 pixels) to the built map: parsing,
    // validation, image decoding and the gain map.
    for (name, resolution) in [
        ("decode_and_gain_map_241x161", 0.25),
        ("decode_and_gain_map_601x401", 0.1),
        ("decode_and_gain_map_1201x801", 0.05),
    ] {
        let document = warehouse_document(resolution);
        group.bench_function(name, |b| {
            b.iter(|| {
                let s = Scenario::from_value(black_box(document.clone())).unwrap();
                let key = MapKey::gain("bench", &s, PhaseMode::Continuous).unwrap();
                irs_answers::map::build(&s, &key, &Progress::default()).unwrap()
            })
        });
    }
    let s = Scenario::from_value(warehouse_document(0.25)).unwrap();
    let key = MapKey::gain("bench", &s, PhaseMode::Continuous).unwrap();
    let map = irs_answers::map::build(&s, &key, &Progress::default()).unwrap();
    // From an office in the north-west to the south-east corner, through the racks.
    let (start, goal) = ([-27.0, 16.0], [26.0, -16.0]);
    for (name, threshold) in [
        ("path_at_minus_76_db", Threshold::Value(-76.0)),
        ("path_at_max_threshold", Threshold::Max),
    ] {
        assert!(
            planner::plan(
                &map,
                map.native_unit(),
                Default::default(),
                start,
                goal,
                threshold,
                1.0
            )
            .unwrap()
            .feasible
        );
        group.bench_function(name, |b| {
            b.iter(|| {
                planner::plan(
                    black_box(&map),
                    map.native_unit(),
                    Default::default(),
                    start,
                    goal,
                    threshold,
                    1.0,
                )
                .unwrap()
            })
        });
    }
    group.finish();
}

/// Any-angle against 8-connected searches (issue: at most 3× the grid query's time) on the
/// paper floor at 2 cm (1001²) and the warehouse at 5 cm (1201 × 801), each at a threshold
/// where the path is nearly straight and one just below the largest feasible; the lengths are
/// printed once, for docs/performance.md.
fn any_angle(c: &mut Criterion) {
    let paper_floor = paper("paper-single-user", |v| {
        v["grid"]["resolution_m"] = 0.02.into();
    });
    let warehouse = Scenario::from_value(warehouse_document(0.05)).unwrap();
    let mut group = c.benchmark_group("any_angle");
    group
        .sample_size(10)
        .measurement_time(Duration::from_secs(10));
    for (floor, s, start, goal) in [
        ("paper_1001x1001", &paper_floor, [-10.0, 0.0], [10.0, 0.0]),
        (
            "warehouse_1201x801",
            &warehouse,
            [-27.0, 16.0],
            [26.0, -16.0],
        ),
    ] {
        let key = MapKey::gain("bench", s, PhaseMode::Continuous).unwrap();
        let map = irs_answers::map::build(s, &key, &Progress::default()).unwrap();
        let graph = CellGraph {
            grid: &map.grid,
            values: &map.values,
            occupied: &map.occupied,
        };
        let cell = |p: [f64; 2]| {
            let (i, j) = map.grid.snap(p[0], p[1]).unwrap();
            map.grid.index(i, j)
        };
        let (from, to) = (cell(start), cell(goal));
        let widest = graph.widest_path_threshold(from, to).unwrap();
        for (level, threshold) in [("wide", widest - 3.0), ("narrow", widest - 0.05)] {
            // A*, the grid search an any-angle query runs itself: the reference its cost is
            // stated against (the grid query the service answers is the jump point search).
            let grid_path = graph.a_star_path(from, to, threshold).unwrap();
            let any = graph.any_angle_path(from, to, threshold).unwrap();
            eprintln!(
                "{floor} {level} (γ = {threshold:.2} dB): grid {:.3} m, any-angle {:.3} m                  ({:.2} % shorter, {} vertices)",
                grid_path.distance_m,
                any.distance_m,
                100.0 * (1.0 - any.distance_m / grid_path.distance_m),
                any.vertices.len()
            );
            group.bench_function(format!("{floor}_{level}_grid"), |b| {
                b.iter(|| graph.a_star_path(from, to, black_box(threshold)))
            });
            group.bench_function(format!("{floor}_{level}_any_angle"), |b| {
                b.iter(|| graph.any_angle_path(from, to, black_box(threshold)))
            });
        }
    }
    group.finish();
}

/// A 100 × 60 m factory hall at 0.1 m (1001 × 601 cells): 40 machines of 2–4 × 1.5–3 m and
/// 1.5–3.1 m high in a 8 × 5 layout, the AP high on the north wall, a 16 × 16 IRS (N = 256) on
/// the south wall. Most links pass near several machines, so this is what the per-source
/// direction index of the obstacles (geometry::SightLines) is for.
fn factory_hall() -> Scenario {
    let mut obstacles = Vec::new();
    for row in 0..5 {
        for column in 0..8 {
            let k = row * 8 + column;
            obstacles.push(serde_json::json!({
                "center": [-40.0 + column as f64 * 11.5, -22.0 + row as f64 * 11.0],
                "size": [2.0 + (k % 3) as f64, 1.5 + (k % 4) as f64 * 0.5],
                "height_m": 1.5 + (k % 5) as f64 * 0.4,
            }));
        }
    }
    Scenario::from_value(serde_json::json!({
        "name": "factory-hall",
        "room": {"x_min": -50.0, "x_max": 50.0, "y_min": -30.0, "y_max": 30.0, "ceiling_m": 6.0},
        "grid": {"resolution_m": 0.1},
        "obstacles": obstacles,
        "ap": {"position": [0.0, 30.0, 4.0], "tx_power_dbm": 20.0, "noise_dbm": -90.0,
               "carrier_ghz": 2.0},
        "irs": {"center": [0.0, -30.0, 3.0], "normal": [0.0, 1.0, 0.0], "nx_sub": 16,
                "nz_sub": 16, "elements_per_sub": 4, "sub_pitch_m": 0.03, "grouping": "coherent"},
        "mru": {"antenna_height_m": 1.0, "v_max_mps": 1.0},
        "srus": [],
        "channel": {"rician_k_db": 3.0, "path_loss": "3gpp_inf_sh"}
    }))
    .unwrap()
}

fn factory(c: &mut Criterion) {
    let s = factory_hall();
    let key = MapKey::gain("bench", &s, PhaseMode::Continuous).unwrap();
    let mut group = c.benchmark_group("factory");
    group.sample_size(10);
    group.bench_function("gain_map_1001x601_40_machines_n256", |b| {
        b.iter(|| irs_answers::map::build(black_box(&s), &key, &Progress::default()).unwrap())
    });
    group.finish();
}

/// Every 0.5 m of the paper floor's four walls (164 IRS poses, 123 valid), ranked by the largest
/// threshold q_I → q_F.
fn placement(c: &mut Criterion) {
    use irs_model::placement::{self, Candidates, Objective, Search, Segment, What};
    let base = Scenario::builtin("paper-single-user").unwrap();
    let corners = [[-10.0, -10.0], [10.0, -10.0], [10.0, 10.0], [-10.0, 10.0]];
    let search = Search {
        what: What::Irs,
        index: 0,
        candidates: Candidates {
            poses: Vec::new(),
            positions: Vec::new(),
            walls: (0..4)
                .map(|k| Segment {
                    from: corners[k],
                    to: corners[(k + 1) % 4],
                })
                .collect(),
            step_m: Some(0.5),
            height_m: None,
        },
        objective: Objective::MaxThreshold {
            start: [-10.0, 0.0],
            goal: [10.0, 0.0],
        },
        phases: None,
    };
    let mut group = c.benchmark_group("placement");
    group.sample_size(10);
    group.bench_function("paper_walls_164_candidates_max_threshold", |b| {
        b.iter(|| {
            placement::place(
                black_box(&base),
                &search,
                &irs_answers::map::ContentIds,
                &Progress::default(),
            )
            .unwrap()
        })
    });
    group.finish();
}

/// A path query's answer on the paper map (−10,0 → 10,0 at −62 dB: 41 waypoints × 60
/// phases), as the service makes it on a miss of its answer cache: the indexed search, the
/// waypoints' eq. 11 phases, the phases written at a precision, the JSON body. Decimals are
/// written as the body is (`phase_text::RoundedPhases`), so `write_phases_1e-4` times only
/// their preparation and the `body_*` benches their text; codes are written by
/// `write_phases`.
fn path_answer(c: &mut Criterion) {
    let s = paper("paper-single-user", |_| {});
    let key = MapKey::gain("bench", &s, PhaseMode::Continuous).unwrap();
    let map = irs_answers::map::build(&s, &key, &Progress::default()).unwrap();
    let index = planner::UnitIndex::new(&map, map.native_unit()).unwrap();
    let plan = || {
        let threshold = Threshold::Value(-62.0);
        planner::plan_indexed(
            &map,
            &index,
            Default::default(),
            [-10.0, 0.0],
            [10.0, 0.0],
            threshold,
            1.0,
        )
        .unwrap()
    };
    let path = plan();
    assert_eq!(path.waypoints.len(), 41);
    let mut group = c.benchmark_group("path_answer");
    group.bench_function("plan_41x41", |b| b.iter(plan));
    for (name, format, precision) in [
        (
            "write_phases_1e-4",
            PhaseFormat::Radians,
            PhasePrecision::TenthMilli,
        ),
        (
            "write_phases_codes",
            PhaseFormat::Codes,
            PhasePrecision::TenthMilli,
        ),
    ] {
        group.bench_function(name, |b| {
            b.iter_batched(
                || path.clone(),
                |path| write_phases(&s, &map, path, format, precision),
                criterion::BatchSize::SmallInput,
            )
        });
    }
    for (name, precision) in [
        ("body_1e-4", PhasePrecision::TenthMilli),
        ("body_full", PhasePrecision::Full),
    ] {
        group.bench_function(name, |b| {
            b.iter(|| {
                let path = write_phases(&s, &map, plan(), PhaseFormat::Radians, precision);
                CheckedPath {
                    path,
                    monte_carlo: None,
                }
                .to_json()
            })
        });
    }
    // The same on the paper floor at 2 cm: a path of about a thousand waypoints, as the
    // service writes one for a fleet on a large map (the search left out).
    let fine = paper("paper-single-user", |v| {
        v["grid"]["resolution_m"] = 0.02.into();
    });
    let key = MapKey::gain("bench", &fine, PhaseMode::Continuous).unwrap();
    let map = irs_answers::map::build(&fine, &key, &Progress::default()).unwrap();
    let index = planner::UnitIndex::new(&map, map.native_unit()).unwrap();
    let long = planner::plan_indexed(
        &map,
        &index,
        Default::default(),
        [-10.0, 0.0],
        [10.0, 0.0],
        Threshold::Value(-62.0),
        1.0,
    )
    .unwrap();
    eprintln!("path_answer/body_1001: {} waypoints", long.waypoints.len());
    group.bench_function("body_1e-4_1001x1001", |b| {
        b.iter_batched(
            || long.clone(),
            |path| {
                let path = write_phases(
                    &fine,
                    &map,
                    path,
                    PhaseFormat::Radians,
                    PhasePrecision::TenthMilli,
                );
                CheckedPath {
                    path,
                    monte_carlo: None,
                }
                .to_json()
            },
            criterion::BatchSize::SmallInput,
        )
    });
    group.finish();
}

/// A lattice route graph of `side` × `side` nodes over the room inside `margin` of its walls,
/// each node joined both ways to its east and north neighbours.
fn lattice_graph(scenario: &Scenario, side: usize, margin: f64) -> RouteGraph {
    let room = &scenario.room;
    let at = |k: usize, lo: f64, hi: f64| {
        lo + margin + (hi - lo - 2.0 * margin) * k as f64 / (side - 1) as f64
    };
    let mut nodes = Vec::new();
    for i in 0..side {
        for j in 0..side {
            nodes.push(GraphNode {
                id: nodes.len().to_string(),
                position: [at(i, room.x_min, room.x_max), at(j, room.y_min, room.y_max)],
            });
        }
    }
    let mut edges = Vec::new();
    let mut join = |a: usize, b: usize, nodes: &[GraphNode]| {
        for (from, to) in [(a, b), (b, a)] {
            edges.push(GraphEdge {
                id: (nodes.len() + edges.len()).to_string(),
                from,
                to,
                points: vec![nodes[from].position, nodes[to].position],
            });
        }
    };
    for i in 0..side {
        for j in 0..side {
            let k = i * side + j;
            if i + 1 < side {
                join(k, k + side, &nodes);
            }
            if j + 1 < side {
                join(k, k + 1, &nodes);
            }
        }
    }
    RouteGraph {
        nodes,
        edges,
        source: std::sync::Arc::new(GraphSource {
            format: GraphFormat::Nav2GeoJson,
            level: None,
            document: "null".into(),
        }),
    }
}

/// Route graphs on the warehouse's 0.25 m gain map: scoring ~10 000 edges (a 50 × 50 lattice,
/// 9 800 edges, 0.8–1.2 m long), and a route query corner to corner on a 100 × 100 lattice
/// (10 000 nodes, 39 600 edges) 3 dB below its widest threshold, on scores kept.
fn route_graphs(c: &mut Criterion) {
    let s = Scenario::from_value(warehouse_document(0.25)).unwrap();
    let key = MapKey::gain("bench", &s, PhaseMode::Continuous).unwrap();
    let map = irs_answers::map::build(&s, &key, &Progress::default()).unwrap();
    let mut group = c.benchmark_group("route_graph");
    let scoring = lattice_graph(&s, 50, 0.5);
    group.bench_function("score_9800_edges_warehouse", |b| {
        b.iter(|| route_graph::score_edges(&map, &map.values, black_box(&scoring)))
    });
    let big = lattice_graph(&s, 100, 0.5);
    let scores = route_graph::score_edges(&map, &map.values, &big);
    let searched = route_graph::ScoredGraph::new(&big, &scores);
    let (start, goal) = (0, big.nodes.len() - 1);
    // 3 dB below the widest route's threshold: most edges open, some closed.
    let threshold = searched.widest_threshold(start, goal).unwrap() - 3.0;
    assert!(searched.shortest_route(start, goal, threshold).is_some());
    group.bench_function("search_layout_10000_nodes", |b| {
        b.iter(|| route_graph::ScoredGraph::new(black_box(&big), &scores))
    });
    group.bench_function("route_10000_nodes", |b| {
        b.iter(|| black_box(&searched).shortest_route(start, goal, threshold))
    });
    group.bench_function("widest_10000_nodes", |b| {
        b.iter(|| black_box(&searched).widest_threshold(start, goal))
    });
    group.finish();
}

criterion_group!(
    benches,
    gain_maps,
    large_grid,
    rate_maps,
    floors,
    any_angle,
    factory,
    placement,
    path_answer,
    route_graphs
);
criterion_main!(benches);
