//! The Rust half of `scripts/vs-python.sh`: times this crate on two workloads and writes what
//! the Python half needs to time NumPy and SciPy on the same ones and to check that all of them
//! computed the same thing.
//!
//! `cargo run --release --example python_comparison -- gain|maze|place OUT_DIR [REPEATS]`
//!
//! - `gain`: the continuous gain map of the paper floor at 2 cm (1001 × 1001 cells), the whole
//!   `radiomap::build` (occupancy, channel model, every cell), on a one-thread and a two-thread
//!   pool; writes `OUT_DIR/gain.npy` (f64 dB, NaN where occupied, shape (nx, ny)).
//! - `maze`: the same floor with its boxes replaced by 19 serpentine walls, and the shortest
//!   path between the maze's two ends over every free cell (a threshold far below any value);
//!   writes `OUT_DIR/maze_free.npy` (u8, 1 where free).
//!
//! - `place`: the placement search of `benches/maps.rs` (an IRS at every 0.5 m of the paper
//!   floor's four walls, 164 poses at 0.5 m cells, ranked by the widest path's threshold from
//!   (−10, 0) to (10, 0)), the whole `placement::place` on a one-thread and a two-thread pool;
//!   the JSON line carries every candidate's pose and score.
//!
//! Each prints one JSON line: the median and minimum of the timed runs, and the results to compare.

use irs_answers::scenario::ScenarioDocument;
use irs_model::phases::PhaseMode;
use irs_model::planner::CellGraph;
use irs_model::radiomap::{MapKey, Progress, RadioMap};
use irs_model::scenario::Scenario;
use std::path::Path;
use std::time::Instant;

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let (Some(workload), Some(out)) = (args.first(), args.get(1)) else {
        eprintln!("usage: python_comparison gain|maze|maze-coarse|place OUT_DIR [REPEATS]");
        std::process::exit(2);
    };
    let repeats: usize = match args.get(2).map(|r| r.parse()) {
        None => 7,
        Some(Ok(r)) if r > 0 => r,
        Some(_) => {
            eprintln!("REPEATS: expected a positive integer");
            std::process::exit(2);
        }
    };
    let out = Path::new(out);
    std::fs::create_dir_all(out).expect("creating OUT_DIR");
    match workload.as_str() {
        "gain" => gain(out, repeats),
        "maze" => maze(out, repeats, 0.02),
        "maze-coarse" => maze(out, repeats, 0.1),
        "place" => place(repeats),
        other => {
            eprintln!("unknown workload {other:?}: expected gain, maze, maze-coarse or place");
            std::process::exit(2);
        }
    }
}

/// The paper single-user floor at 2 cm, with `edit` applied to its document.
fn paper_floor(edit: impl FnOnce(&mut serde_json::Value)) -> Scenario {
    Scenario::builtin_with("paper-single-user", |v| {
        v["grid"]["resolution_m"] = 0.02.into();
        edit(v);
    })
    .expect("built in")
    .expect("a valid scenario")
}

fn build(s: &Scenario) -> RadioMap {
    let key = MapKey::gain("comparison", s, PhaseMode::Continuous).expect("a gain key");
    irs_answers::map::build(s, &key, &Progress::default()).expect("not cancelled")
}

/// Seconds of `run` over `repeats` runs: (median, minimum).
fn timed(repeats: usize, mut run: impl FnMut()) -> (f64, f64) {
    let mut seconds: Vec<f64> = (0..repeats)
        .map(|_| {
            let t = Instant::now();
            run();
            t.elapsed().as_secs_f64()
        })
        .collect();
    seconds.sort_by(f64::total_cmp);
    (seconds[seconds.len() / 2], seconds[0])
}

fn pool(threads: usize) -> rayon::ThreadPool {
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .expect("a thread pool")
}

fn gain(out: &Path, repeats: usize) {
    let s = paper_floor(|_| {});
    let map = build(&s);
    let (one_median, one_min) = pool(1).install(|| timed(repeats, || drop(build(&s))));
    let (two_median, two_min) = pool(2).install(|| timed(repeats, || drop(build(&s))));
    write_npy(
        &out.join("gain.npy"),
        &[map.grid.nx, map.grid.ny],
        map.values.iter().copied(),
    );
    println!(
        "{}",
        serde_json::json!({
            "workload": "gain", "nx": map.grid.nx, "ny": map.grid.ny, "repeats": repeats,
            "one_thread_s": {"median": one_median, "min": one_min},
            "two_threads_s": {"median": two_median, "min": two_min},
        })
    );
}

/// The serpentine: 19 walls 1 m apart across the 20 m floor, each leaving a 1 m gap at the top
/// or the bottom in turn, so the only way from the west end to the east end runs up and down
/// every corridor (about 380 m, 19 000 cells at 2 cm).
fn maze_walls() -> serde_json::Value {
    let walls: Vec<serde_json::Value> = (0..19)
        .map(|k| {
            let x = -9.0 + k as f64;
            let (y0, y1) = if k % 2 == 0 {
                (-10.0, 9.0)
            } else {
                (-9.0, 10.0)
            };
            serde_json::json!({"from": [x, y0], "to": [x, y1], "thickness_m": 0.1, "height_m": 2.5})
        })
        .collect();
    walls.into()
}

fn maze(out: &Path, repeats: usize, resolution_m: f64) {
    let s = paper_floor(|v| {
        v["obstacles"] = serde_json::json!([]);
        v["walls"] = maze_walls();
        v["grid"]["resolution_m"] = resolution_m.into();
    });
    let map = build(&s);
    let graph = CellGraph {
        grid: &map.grid,
        values: &map.values,
        occupied: &map.occupied,
    };
    let (start, goal) = (
        map.grid.index(0, 0),
        map.grid.index(map.grid.nx - 1, map.grid.ny - 1),
    );
    // Every free cell is feasible: the path is the maze's, not the radio map's. The search is
    // the one a one-off query runs, its jump point index built in the time.
    let threshold = -1000.0;
    let path = graph
        .shortest_path(start, goal, threshold)
        .expect("the maze's ends are joined");
    let (median, min) = timed(repeats, || {
        drop(graph.shortest_path(start, goal, threshold));
    });
    let free_file = format!("maze_free_{}.npy", map.grid.nx);
    write_npy(
        &out.join(&free_file),
        &[map.grid.nx, map.grid.ny],
        map.occupied.iter().map(|&o| if o { 0u8 } else { 1u8 }),
    );
    println!(
        "{}",
        serde_json::json!({
            "workload": "maze", "nx": map.grid.nx, "ny": map.grid.ny, "repeats": repeats,
            "resolution_m": map.grid.resolution_m, "free_file": free_file,
            "start": [0, 0], "goal": [map.grid.nx - 1, map.grid.ny - 1],
            "distance_m": path.distance_m, "waypoints": path.cells.len(),
            "shortest_path_s": {"median": median, "min": min},
        })
    );
}

fn place(repeats: usize) {
    use irs_model::placement::{self, Candidates, Objective, Search, Segment, What};
    let base = Scenario::builtin("paper-single-user").expect("built in");
    let corners = [[-10.0, -10.0], [10.0, -10.0], [10.0, 10.0], [-10.0, 10.0]];
    let (start, goal) = ([-10.0, 0.0], [10.0, 0.0]);
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
        objective: Objective::MaxThreshold { start, goal },
        phases: None,
    };
    let run = || {
        placement::place(
            &base,
            &search,
            &irs_answers::map::ContentIds,
            &Progress::default(),
        )
        .expect("a valid search")
    };
    let answer = run().answer;
    let (one_median, one_min) = pool(1).install(|| timed(repeats, || drop(run())));
    let (two_median, two_min) = pool(2).install(|| timed(repeats, || drop(run())));
    let candidates: Vec<serde_json::Value> = answer
        .candidates
        .iter()
        .map(|c| serde_json::json!({"center": c.center, "normal": c.normal, "score": c.score}))
        .collect();
    println!(
        "{}",
        serde_json::json!({
            "workload": "place", "repeats": repeats, "start": start, "goal": goal,
            "rejected": answer.rejected.len(), "candidates": candidates,
            "one_thread_s": {"median": one_median, "min": one_min},
            "two_threads_s": {"median": two_median, "min": two_min},
        })
    );
}

fn write_npy<T: npyz::Serialize + npyz::AutoSerialize>(
    path: &Path,
    shape: &[usize],
    values: impl IntoIterator<Item = T>,
) {
    use npyz::WriterBuilder;
    let mut bytes = Vec::new();
    let shape: Vec<u64> = shape.iter().map(|&n| n as u64).collect();
    let mut writer = npyz::WriteOptions::new()
        .default_dtype()
        .shape(&shape)
        .writer(&mut bytes)
        .begin_nd()
        .expect("writing into memory cannot fail");
    writer
        .extend(values)
        .expect("writing into memory cannot fail");
    writer.finish().expect("writing into memory cannot fail");
    std::fs::write(path, bytes).expect("writing the .npy file");
}
