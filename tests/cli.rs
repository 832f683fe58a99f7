//! The binary as a user runs it: output bodies, snapping, and exit code 2 with a message naming
//! the field for every kind of bad input.

use std::process::Command;

fn run(args: &[&str]) -> (i32, String, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_irs-planner"))
        .args(args)
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .expect("the binary runs");
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&out.stdout).into(),
        String::from_utf8_lossy(&out.stderr).into(),
    )
}

const SMALL: &str = "scenarios/small-test.json";

/// A gain-map path across the small floor at the largest feasible threshold.
const SMALL_GAIN_PLAN: [&str; 11] = [
    "plan",
    "--scenario",
    SMALL,
    "--kind",
    "gain",
    "--start",
    "0.5,0.5",
    "--goal",
    "5.5,3.5",
    "--max-threshold",
    "--quiet",
];

#[test]
fn plan_prints_the_path_body() {
    let (code, out, err) = run(&[
        "plan",
        "--scenario",
        SMALL,
        "--kind",
        "gain",
        "--start",
        "0.4,0.4",
        "--goal",
        "5.5,3.5",
        "--max-threshold",
        "--quiet",
    ]);
    assert_eq!(code, 0, "{err}");
    let body: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert_eq!(body["feasible"], true);
    assert_eq!(body["start"]["snapped"], true);
    assert_eq!(body["start"]["x"], 0.5);
    assert_eq!(body["threshold"], body["max_feasible_threshold"]);
    let waypoints = body["waypoints"].as_array().unwrap();
    assert_eq!(waypoints.first().unwrap()["i"], 1);
    // One IRS: one phase vector, of its N = 4 sub-surfaces.
    let phases = waypoints[0]["irs_phases_rad"].as_array().unwrap();
    assert_eq!(phases.len(), 1);
    assert_eq!(phases[0].as_array().unwrap().len(), 4);
    let distance = body["distance_m"].as_f64().unwrap();
    assert!((body["travel_time_s"].as_f64().unwrap() - distance / 0.5).abs() < 1e-9);
}

/// `--phase-format codes`: each surface's phases as one base64 string of 16-bit codes (N = 4:
/// eight bytes, twelve characters); a precision is for radians only (exit 2, naming it).
#[test]
fn plan_writes_phase_codes_on_request() {
    let args = [&SMALL_GAIN_PLAN[..], &["--phase-format", "codes"]].concat();
    let (code, out, err) = run(&args);
    assert_eq!(code, 0, "{err}");
    let body: serde_json::Value = serde_json::from_str(&out).unwrap();
    let waypoint = &body["waypoints"][0];
    assert!(waypoint.get("irs_phases_rad").is_none());
    assert_eq!(waypoint["irs_phase_codes"][0].as_str().unwrap().len(), 12);
    let (code, _, err) = run(&[&args[..], &["--phase-precision", "1e-2"]].concat());
    assert_eq!(code, 2);
    assert!(err.contains("--phase-precision"), "{err}");
}

#[test]
fn rate_plan_carries_powers_order_and_monte_carlo() {
    let (code, out, err) = run(&[
        "plan",
        "--scenario",
        SMALL,
        "--kind",
        "rate",
        "--access",
        "noma",
        "--start",
        "0.5,0.5",
        "--goal",
        "5.5,3.0",
        "--threshold",
        "1.0",
        "--monte-carlo",
        "2000",
        "--quiet",
    ]);
    assert_eq!(code, 0, "{err}");
    let body: serde_json::Value = serde_json::from_str(&out).unwrap();
    let wp = &body["waypoints"][0];
    assert_eq!(wp["power_w"].as_array().unwrap().len(), 2);
    assert_eq!(wp["decoding_order"].as_array().unwrap().len(), 2);
    assert_eq!(body["monte_carlo"]["draws"], 2000);
}

#[test]
fn png_output_is_written() {
    let file = std::env::temp_dir().join(format!("irs-cli-{}.png", std::process::id()));
    let (code, _, err) = run(&[&SMALL_GAIN_PLAN[..], &["--png", file.to_str().unwrap()]].concat());
    assert_eq!(code, 0, "{err}");
    let bytes = std::fs::read(&file).unwrap();
    assert_eq!(&bytes[..8], b"\x89PNG\r\n\x1a\n");
    let _ = std::fs::remove_file(file);
}

#[test]
fn map_prints_the_map_body() {
    let (code, out, err) = run(&[
        "map",
        "--scenario",
        SMALL,
        "--kind",
        "gain",
        "--phases",
        "2",
        "--quiet",
    ]);
    assert_eq!(code, 0, "{err}");
    let body: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert_eq!(body["unit"], "dB");
    assert_eq!(body["key"]["phases"], 2);
    assert_eq!(
        body["values"].as_array().unwrap().len(),
        body["grid"]["nx"].as_u64().unwrap() as usize
    );
}

/// A script tells "no path meets the threshold" (exit 3, the answer still printed with its
/// reason) from bad input (exit 2) and from a path (exit 0).
#[test]
fn no_path_exits_3_with_the_answer_printed() {
    let (code, out, err) = run(&[
        "plan",
        "--scenario",
        SMALL,
        "--kind",
        "gain",
        "--start",
        "0.5,0.5",
        "--goal",
        "5.5,3.5",
        "--threshold",
        "10",
        "--quiet",
    ]);
    assert_eq!(code, 3, "{err}");
    let body: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert_eq!(body["feasible"], false);
    assert_eq!(body["reason"], "start_below_threshold");
    assert!(err.contains("start_below_threshold"), "{err}");
    let (code, _, _) = run(&SMALL_GAIN_PLAN);
    assert_eq!(code, 0);
}

#[test]
fn bad_input_exits_2_and_names_the_field() {
    let dir = std::env::temp_dir().join(format!("irs-cli-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let bad = dir.join("bad.json");
    let mut v: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(format!("{}/{SMALL}", env!("CARGO_MANIFEST_DIR"))).unwrap(),
    )
    .unwrap();
    v["mru"]["v_max_mps"] = (-1.0).into();
    std::fs::write(&bad, v.to_string()).unwrap();
    let bad = bad.to_str().unwrap();
    let cases: Vec<(Vec<&str>, &str)> = vec![
        (
            vec!["map", "--scenario", bad, "--kind", "gain"],
            "mru.v_max_mps",
        ),
        (
            vec!["map", "--scenario", "missing.json", "--kind", "gain"],
            "missing.json",
        ),
        (
            vec![
                "map",
                "--scenario",
                SMALL,
                "--kind",
                "gain",
                "--phases",
                "0",
            ],
            "--phases",
        ),
        (
            vec![
                "map",
                "--scenario",
                SMALL,
                "--kind",
                "gain",
                "--access",
                "oma",
            ],
            "access",
        ),
        (
            vec!["map", "--scenario", SMALL, "--kind", "volume"],
            "--kind",
        ),
        (
            vec![
                "plan",
                "--scenario",
                SMALL,
                "--kind",
                "gain",
                "--start",
                "99,0",
                "--goal",
                "1,1",
                "--threshold",
                "-70",
            ],
            "start",
        ),
        (
            vec![
                "plan",
                "--scenario",
                SMALL,
                "--kind",
                "gain",
                "--start",
                "1,1",
                "--goal",
                "1,1",
            ],
            "--threshold",
        ),
        (
            vec![
                "plan",
                "--scenario",
                SMALL,
                "--kind",
                "gain",
                "--start",
                "1;1",
                "--goal",
                "1,1",
                "--max-threshold",
            ],
            "--start",
        ),
        (
            vec![
                "plan",
                "--scenario",
                SMALL,
                "--kind",
                "rate",
                "--start",
                "1,1",
                "--goal",
                "1,1",
                "--max-threshold",
                "--monte-carlo",
                "0",
            ],
            "--monte-carlo",
        ),
    ];
    for (args, needle) in cases {
        let (code, _, err) = run(&args);
        assert_eq!(code, 2, "{args:?}: {err}");
        assert!(
            err.contains(needle),
            "{args:?}: {err:?} does not name {needle}"
        );
    }
}

/// A server that cannot run is a runtime failure (exit 1), not bad input; a setting that is
/// wrong is the operator's input (exit 2, naming it). (An invalid file in the scenarios
/// directory is skipped with a log line, not fatal: tests/service.rs.)
#[test]
fn serve_failures_are_runtime_errors_unless_the_input_is_bad() {
    let taken = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let addr = taken.local_addr().unwrap().to_string();
    let (code, _, err) = run(&["serve", "--bind", &addr, "--scenarios", "no-such-dir"]);
    assert_eq!(code, 1, "{err}");
    assert!(err.contains("--bind"), "{err}");

    let (code, _, err) = run(&[
        "serve",
        "--bind",
        "127.0.0.1:0",
        "--scenarios",
        "no-such-dir",
        "--cors-origin",
        "ftp://example.org",
    ]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("--cors-origin"), "{err}");
}

const WAREHOUSE: &str = "scenarios/warehouse/warehouse.json";

/// `fleet` prints the plan of the robots file and draws their routes; a bad robots file exits 2
/// naming the robot's field.
#[test]
fn fleet_plans_the_robots_file_and_draws_their_routes() {
    let dir = scratch("fleet");
    let png = dir.join("fleet.png");
    let (code, out, err) = run(&[
        "fleet",
        "--scenario",
        "scenarios/paper-single-user.json",
        "--kind",
        "gain",
        "--robots",
        "scenarios/fleets/paper-three.json",
        "--quiet",
        "--png",
        png.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{err}");
    let plan = json(&out);
    assert_eq!(plan["names"], serde_json::json!(["a", "b", "c"]));
    assert_eq!(plan["violations"], serde_json::json!([]));
    assert!(
        plan["robots"]
            .as_array()
            .unwrap()
            .iter()
            .all(|r| r["arrival_step"].is_u64())
    );
    assert_eq!(&std::fs::read(&png).unwrap()[..8], b"\x89PNG\r\n\x1a\n");
    let bad = dir.join("robots.json");
    std::fs::write(
        &bad,
        r#"{"robots": [{"start": [0, 9], "goal": [40, 0], "threshold": -80}]}"#,
    )
    .unwrap();
    let (code, _, err) = run(&[
        "fleet",
        "--scenario",
        "scenarios/paper-single-user.json",
        "--kind",
        "gain",
        "--robots",
        bad.to_str().unwrap(),
        "--quiet",
    ]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("robots[0].goal"), "{err}");
    let _ = std::fs::remove_dir_all(dir);
}

/// A scratch folder for one test.
fn scratch(name: &str) -> std::path::PathBuf {
    let dir = std::env::temp_dir().join(format!("irs-cli-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn json(text: &str) -> serde_json::Value {
    serde_json::from_str(text).unwrap()
}

/// The warehouse scenario without its floor plan (its route graph inline, its file staying
/// beside the original), written into `dir`; with `irs_on_room_wall`
/// its IRS moves from the floor plan's wall face (x = 29.75) to the room's wall (x = 30), where
/// it hangs whatever floor plan is given.
fn bare_warehouse(dir: &std::path::Path, irs_on_room_wall: bool) -> std::path::PathBuf {
    let mut bare = json(&std::fs::read_to_string(WAREHOUSE).unwrap());
    bare.as_object_mut().unwrap().remove("floor_plan");
    let lanes = json(&std::fs::read_to_string("scenarios/warehouse/lanes.geojson").unwrap());
    bare["route_graph"] = serde_json::json!({"format": "nav2_geojson", "graph": lanes});
    if irs_on_room_wall {
        bare["irs"]["center"] = serde_json::json!([30.0, -4.0, 2.5]);
    }
    let path = dir.join("bare.json");
    std::fs::write(&path, bare.to_string()).unwrap();
    path
}

/// The warehouse's floor plan named in its file and given by `--floor-plan` to the same floor
/// without one are the same scenario (the id hashes the pixels, not a path); `scenario` prints
/// the inline form the API takes.
#[test]
fn floor_plans_come_from_scenario_files_or_the_flag() {
    let (code, body, err) = run(&["map", "--scenario", WAREHOUSE, "--kind", "gain", "--quiet"]);
    assert_eq!(code, 0, "{err}");
    let from_file = json(&body);
    assert_eq!(from_file["grid"]["nx"], 241);
    assert_eq!(from_file["grid"]["ny"], 161);

    let dir = scratch("flag");
    let bare_path = bare_warehouse(&dir, false);
    let bare_path = bare_path.to_str().unwrap();
    let (code, body, err) = run(&[
        "map",
        "--scenario",
        bare_path,
        "--floor-plan",
        "scenarios/warehouse/map.yaml",
        "--kind",
        "gain",
        "--quiet",
    ]);
    assert_eq!(code, 0, "{err}");
    assert_eq!(json(&body)["map_id"], from_file["map_id"]);
    // Another obstacle height is another floor.
    let (code, body, _) = run(&[
        "map",
        "--scenario",
        bare_path,
        "--floor-plan",
        "scenarios/warehouse/map.yaml",
        "--obstacle-height",
        "3",
        "--kind",
        "gain",
        "--quiet",
    ]);
    assert_eq!(code, 0);
    assert_ne!(json(&body)["map_id"], from_file["map_id"]);

    let (code, body, err) = run(&["scenario", "--scenario", WAREHOUSE]);
    assert_eq!(code, 0, "{err}");
    let inline = json(&body);
    let plan = &inline["floor_plan"];
    assert!(plan.get("map").is_none());
    assert_eq!(plan["resolution"], 0.05);
    assert_eq!(plan["obstacle_height_m"], 5.0, "the ceiling, spelled out");
    assert!(
        plan["image"].as_str().unwrap().starts_with("UDU"),
        "base64 of \"P5\""
    );
}

/// A 120 × 80 RGB PNG (every pixel 254, 254, 254): a map saved in colour.
static RGB_PNG_120_BY_80: std::sync::LazyLock<Vec<u8>> = std::sync::LazyLock::new(|| {
    use base64::Engine;
    base64::engine::general_purpose::STANDARD
        .decode(
            "iVBORw0KGgoAAAANSUhEUgAAAHgAAABQCAIAAABd+SbeAAAAfUlEQVR42u3QMQ0AAAwDoPoX3dTFsgMkkHIiC\
             kSLRrRo0YgWjWjRohEtGtGiRSNaNKJFi0a0aESLFo1o0YgWLRrRohEtWjSiRSNatGhEi0a0aNGIFo1o0a\
             IRLRrRokUjWjSiRYtGtGhEixaNaNGIFi0a0aIRLVo0okUj+o8BCF6lgohDpfAAAAAASUVORK5CYII=",
        )
        .expect("base64")
});

/// A scenario file that is not a regular file, or repeats a key, exits 2 naming the reason.
#[cfg(unix)]
#[test]
fn scenario_files_are_regular_files_with_unique_keys() {
    let dir = scratch("scenario-files");
    let fifo = dir.join("fifo.json");
    let made = Command::new("mkfifo").arg(&fifo).status().expect("mkfifo");
    assert!(made.success());
    // Opened as a plain file, a FIFO without a writer would block the command for ever.
    let (code, _, err) = run(&["scenario", "--scenario", fifo.to_str().unwrap()]);
    assert_eq!(code, 2, "{err}");
    assert!(
        err.contains("fifo.json") && err.contains("not a regular file (a FIFO)"),
        "{err}"
    );
    let (code, _, err) = run(&["scenario", "--scenario", dir.to_str().unwrap()]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("not a regular file (a directory)"), "{err}");
    let small = std::fs::read_to_string(SMALL).unwrap();
    let twice = dir.join("twice.json");
    std::fs::write(&twice, small.replacen("{", "{\"name\": \"a\", ", 1)).unwrap();
    let text = std::fs::read_to_string(&twice).unwrap();
    assert!(
        text.matches("\"name\"").count() == 2,
        "the file repeats `name`"
    );
    let (code, _, err) = run(&["scenario", "--scenario", twice.to_str().unwrap()]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("$: duplicate key `name`"), "{err}");
}

/// Bad map files exit 2 naming the field, whether the scenario names them or the flag does.
#[test]
fn bad_map_files_exit_2_naming_the_field() {
    let dir = scratch("bad-maps");
    let yaml = |image: &str, extra: &str| {
        format!(
            "image: {image}\nresolution: 0.5\norigin: [-30.0, -20.0, 0.0]\nnegate: 0\n\
             occupied_thresh: 0.65\nfree_thresh: 0.25\n{extra}"
        )
    };
    // 120 × 80 pixels of 0.5 m cover the warehouse room.
    let mut good = b"P5\n120 80\n255\n".to_vec();
    good.extend(std::iter::repeat_n(254u8, 120 * 80));
    let files: Vec<(&str, Vec<u8>, String)> = vec![
        (
            "truncated",
            good[..good.len() - 100].to_vec(),
            yaml("truncated.pgm", ""),
        ),
        (
            "magic",
            b"P6\n1 1\n255\n\0\0\0".to_vec(),
            yaml("magic.pgm", ""),
        ),
        (
            "deep",
            b"P5\n1 1\n65535\n\0\0".to_vec(),
            yaml("deep.pgm", ""),
        ),
        (
            "short",
            b"P5\n120 80\n255\n\xfe\xfe".to_vec(),
            yaml("short.pgm", ""),
        ),
        (
            "small",
            b"P5\n10 10\n255\n"
                .iter()
                .copied()
                .chain([254u8; 100])
                .collect(),
            yaml("small.pgm", ""),
        ),
        (
            "nokey",
            good.clone(),
            yaml("nokey.pgm", "").replace("resolution: 0.5\n", ""),
        ),
        (
            "yaw",
            good.clone(),
            yaml("yaw.pgm", "").replace("0.0]", "0.3]"),
        ),
        // Read as a plain file, /dev/zero would grow without end.
        ("zero", Vec::new(), yaml("/dev/zero", "")),
        (
            "nan",
            good.clone(),
            yaml("nan.pgm", "").replace("resolution: 0.5", "resolution: .nan"),
        ),
        ("rgb", RGB_PNG_120_BY_80.clone(), yaml("rgb.pgm", "")),
    ];
    let expected = [
        ("truncated", "floor_plan.image"),
        ("magic", "floor_plan.image"),
        ("deep", "16-bit"),
        ("short", "floor_plan.image"),
        ("small", "floor_plan: the map covers"),
        ("nokey", "resolution"),
        ("yaw", "floor_plan.origin"),
        ("zero", "/dev/zero (the image named by"),
        ("nan", "resolution: must be a finite number, got NaN"),
        (
            "rgb",
            "is RGB: a floor plan is 8-bit grey; convert it to grayscale",
        ),
    ];
    let bare_path = bare_warehouse(&dir, true);
    for ((name, image, text), (_, needle)) in files.iter().zip(expected) {
        std::fs::write(dir.join(format!("{name}.pgm")), image).unwrap();
        let map_yaml = dir.join(format!("{name}.yaml"));
        std::fs::write(&map_yaml, text).unwrap();
        let (code, _, err) = run(&[
            "map",
            "--scenario",
            bare_path.to_str().unwrap(),
            "--floor-plan",
            map_yaml.to_str().unwrap(),
            "--kind",
            "gain",
            "--quiet",
        ]);
        assert_eq!(code, 2, "{name}: {err}");
        assert!(
            err.contains("--floor-plan") && err.contains(needle),
            "{name}: {err}"
        );
    }
    // The /dev/zero case names the reason too.
    let (_, _, err) = run(&[
        "scenario",
        "--scenario",
        bare_path.to_str().unwrap(),
        "--floor-plan",
        dir.join("zero.yaml").to_str().unwrap(),
    ]);
    assert!(
        err.contains("not a regular file (a character device)"),
        "{err}"
    );
    // The good image on the same floor works.
    std::fs::write(dir.join("good.pgm"), &good).unwrap();
    std::fs::write(dir.join("good.yaml"), yaml("good.pgm", "")).unwrap();
    let (code, _, err) = run(&[
        "map",
        "--scenario",
        bare_path.to_str().unwrap(),
        "--floor-plan",
        dir.join("good.yaml").to_str().unwrap(),
        "--kind",
        "gain",
        "--quiet",
    ]);
    assert_eq!(code, 0, "{err}");
}

/// `export` writes the two masks and the array; the keep-out mask, read back as the floor plan
/// of the same room, marks exactly the cells below the threshold (and the occupied ones).
#[test]
fn export_writes_masks_that_read_back_as_floor_plans() {
    let dir = scratch("export");
    let out = dir.join("out");
    let (code, body, err) = run(&[
        "export",
        "--scenario",
        WAREHOUSE,
        "--kind",
        "gain",
        "--quiet",
        "--threshold",
        "-70",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{err}");
    assert_eq!(json(&body)["files"].as_array().unwrap().len(), 5);
    for name in [
        "keepout.yaml",
        "keepout.pgm",
        "cost.yaml",
        "cost.pgm",
        "map.npy",
    ] {
        assert!(out.join(name).is_file(), "{name}");
    }
    let (_, map_body, _) = run(&["map", "--scenario", WAREHOUSE, "--kind", "gain", "--quiet"]);
    let map = json(&map_body);
    // A 1 cm mask is nothing to hang the IRS on: it goes on the room's east wall.
    let bare_path = bare_warehouse(&dir, true);
    let (code, again, err) = run(&[
        "map",
        "--scenario",
        bare_path.to_str().unwrap(),
        "--floor-plan",
        out.join("keepout.yaml").to_str().unwrap(),
        "--obstacle-height",
        "0.01",
        "--kind",
        "gain",
        "--quiet",
    ]);
    assert_eq!(code, 0, "{err}");
    let again = json(&again);
    let cells = |m: &serde_json::Value| -> Vec<Option<f64>> {
        m["values"]
            .as_array()
            .unwrap()
            .iter()
            .flat_map(|row| row.as_array().unwrap().iter().map(|v| v.as_f64()))
            .collect()
    };
    let expected: Vec<bool> = cells(&map)
        .iter()
        .map(|v| !v.is_some_and(|v| v >= -70.0))
        .collect();
    let got: Vec<bool> = cells(&again).iter().map(|v| v.is_none()).collect();
    assert_eq!(got, expected);
    let (code, _, err) = run(&[
        "export",
        "--scenario",
        WAREHOUSE,
        "--kind",
        "gain",
        "--quiet",
        "--threshold",
        "-30",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert_eq!(code, 2);
    assert!(err.contains("--best"), "{err}");
}

/// `place` ranks wall positions and prints the ranking; `--png` draws the best; bad searches
/// exit 2 naming the flag.
#[test]
fn place_prints_the_ranking_and_draws_the_best() {
    let dir = scratch("place");
    let png = dir.join("best.png");
    let (code, body, err) = run(&[
        "place",
        "--scenario",
        "scenarios/paper-single-user.json",
        "--wall=-10,-10:10,-10",
        "--step",
        "2",
        "--objective",
        "max_threshold",
        "--start=-10,0",
        "--goal",
        "10,0",
        "--quiet",
        "--png",
        png.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{err}");
    let answer = json(&body);
    // Eleven samples 2 m apart; the two at the room's corners move inward by half the
    // surface's width (10 sub-surfaces of 7.5 mm), so the whole surface lies on the wall.
    let candidates = answer["candidates"].as_array().unwrap();
    assert_eq!(candidates.len(), 11);
    assert_eq!(answer["rejected"].as_array().unwrap().len(), 0);
    let xs: Vec<f64> = candidates
        .iter()
        .map(|c| c["center"][0].as_f64().unwrap())
        .collect();
    let lowest = xs.iter().copied().fold(f64::INFINITY, f64::min);
    let highest = xs.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    assert!((lowest + 10.0 - 0.0375).abs() < 1e-9, "{xs:?}");
    assert!((highest - 10.0 + 0.0375).abs() < 1e-9, "{xs:?}");
    assert_eq!(
        answer["candidates"][0]["center"],
        serde_json::json!([0.0, -10.0, 2.0])
    );
    assert!(std::fs::read(&png).unwrap().starts_with(b"\x89PNG"));
    for (args, needle) in [
        (vec!["--objective", "coverage"], "--objective coverage"),
        (
            vec!["--objective", "widest", "--threshold=-60"],
            "--objective",
        ),
        (
            vec!["--objective", "coverage", "--threshold=-60", "--index", "3"],
            "--index",
        ),
    ] {
        let mut all = vec![
            "place",
            "--scenario",
            "scenarios/paper-single-user.json",
            "--wall=-10,-10:10,-10",
            "--step",
            "2",
            "--quiet",
        ];
        all.extend(args);
        let (code, _, err) = run(&all);
        assert_eq!(code, 2, "{all:?}: {err}");
        assert!(err.contains(needle), "{all:?}: {err}");
    }
}

/// The fields of a ROS 2 message type as its vendored `.msg` definition lists them
/// (tests/data/ros2-msgs): (type, name), defaults and comments dropped.
fn msg_fields(package: &str, name: &str) -> Vec<(String, String)> {
    let file = format!(
        "{}/tests/data/ros2-msgs/{package}__{name}.msg",
        env!("CARGO_MANIFEST_DIR")
    );
    std::fs::read_to_string(&file)
        .unwrap_or_else(|e| panic!("{file}: {e}"))
        .lines()
        .map(|l| l.split('#').next().unwrap().trim())
        .filter(|l| !l.is_empty())
        .map(|l| {
            let mut words = l.split_whitespace();
            (
                words.next().unwrap().to_string(),
                words.next().unwrap().to_string(),
            )
        })
        .collect()
}

/// Checks `value` against message type `ty` (seen from `package`) as a ROS 2 JSON bridge would
/// read it: every field of the definition present with its type, no field beyond them.
fn check_msg(value: &serde_json::Value, ty: &str, package: &str, at: &str) {
    if let Some(element) = ty.strip_suffix("[]") {
        for (k, item) in value
            .as_array()
            .unwrap_or_else(|| panic!("{at}: not an array"))
            .iter()
            .enumerate()
        {
            check_msg(item, element, package, &format!("{at}[{k}]"));
        }
        return;
    }
    match ty {
        "float64" | "float32" => assert!(value.is_number(), "{at}: {value} is not a number"),
        "string" => assert!(value.is_string(), "{at}: {value} is not a string"),
        "int32" => {
            let v = value
                .as_i64()
                .unwrap_or_else(|| panic!("{at}: {value} is not an integer"));
            assert!(i32::try_from(v).is_ok(), "{at}: {v} overflows int32");
        }
        "uint32" => {
            let v = value
                .as_u64()
                .unwrap_or_else(|| panic!("{at}: {value} is not unsigned"));
            assert!(u32::try_from(v).is_ok(), "{at}: {v} overflows uint32");
        }
        _ => {
            let (pkg, name) = ty.split_once('/').unwrap_or((package, ty));
            let fields = msg_fields(pkg, name);
            let object = value
                .as_object()
                .unwrap_or_else(|| panic!("{at}: not an object"));
            let names: Vec<&str> = fields.iter().map(|(_, n)| n.as_str()).collect();
            for key in object.keys() {
                assert!(
                    names.contains(&key.as_str()),
                    "{at}: {key} is not a field of {ty}"
                );
            }
            for (field_ty, field) in &fields {
                let inner = object
                    .get(field)
                    .unwrap_or_else(|| panic!("{at}: {ty} lacks {field}"));
                check_msg(inner, field_ty, pkg, &format!("{at}.{field}"));
            }
        }
    }
}

/// `plan --unit` and `--path-shape`: an RSSI threshold selects the path of the gain threshold
/// 20 dB lower (20 dBm, no antenna gains), labelled dBm; any-angle is never longer.
#[test]
fn plan_takes_units_and_path_shapes() {
    let plan = |extra: &[&str]| -> serde_json::Value {
        let args = [
            &[
                "plan",
                "--scenario",
                "scenarios/paper-single-user.json",
                "--kind",
                "gain",
                "--start=-10,0",
                "--goal",
                "10,0",
                "--quiet",
            ][..],
            extra,
        ]
        .concat();
        let (code, out, err) = run(&args);
        assert_eq!(code, 0, "{err}");
        serde_json::from_str(&out).unwrap()
    };
    let db = plan(&["--threshold=-61"]);
    let dbm = plan(&["--threshold=-41", "--unit", "dbm"]);
    assert_eq!(
        (db["unit"].as_str(), dbm["unit"].as_str()),
        (Some("dB"), Some("dBm"))
    );
    assert_eq!(db["distance_m"], dbm["distance_m"]);
    let any = plan(&["--threshold=-61", "--path-shape", "any_angle"]);
    assert_eq!(any["path_shape"], "any_angle");
    assert!(any["distance_m"].as_f64().unwrap() < db["distance_m"].as_f64().unwrap());
    let (code, _, err) = run(&[
        "plan",
        "--scenario",
        "scenarios/paper-single-user.json",
        "--kind",
        "gain",
        "--start=-10,0",
        "--goal",
        "10,0",
        "--threshold=5",
        "--unit",
        "mbps",
        "--quiet",
    ]);
    assert_eq!(code, 2, "{err}");
    assert!(
        err.contains("--unit") && err.contains("bandwidth_mhz"),
        "{err}"
    );
}

/// `plan --tolerance`: a start inside the small room's box moves to the nearest free cell
/// within the tolerance, and says so; without it there is no path (exit 3, start_occupied).
#[test]
fn plan_moves_an_end_within_its_tolerance() {
    let args = |tolerance: &str| {
        vec![
            "plan",
            "--scenario",
            SMALL,
            "--kind",
            "gain",
            "--start",
            "3,2",
            "--goal",
            "0.5,0.5",
            "--max-threshold",
            "--quiet",
            "--tolerance",
            tolerance,
        ]
        .into_iter()
        .map(String::from)
        .collect::<Vec<_>>()
    };
    let run_with = |t: &str| {
        let a = args(t);
        let refs: Vec<&str> = a.iter().map(String::as_str).collect();
        run(&refs)
    };
    let (code, out, _) = run_with("0");
    assert_eq!(code, 3);
    let stuck: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert_eq!(stuck["reason"], "start_occupied");
    let (code, out, err) = run_with("1");
    assert_eq!(code, 0, "{err}");
    let moved: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert_eq!(moved["start"]["moved"], true);
    let (x, y) = (
        moved["start"]["x"].as_f64().unwrap(),
        moved["start"]["y"].as_f64().unwrap(),
    );
    assert!((x - 3.0).hypot(y - 2.0) <= 1.0);
    let (code, _, err) = run_with("-1");
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("--tolerance"), "{err}");
}

/// `plan --output nav-msgs-path` writes a nav_msgs/Path as ROS 2 defines it (the vendored
/// definitions of common_interfaces and rcl_interfaces), in the frame asked for; `--output csv`
/// one line per waypoint; a Monte Carlo report belongs to the JSON answer only.
#[test]
fn a_path_exports_as_nav_msgs_and_csv() {
    let mut args = SMALL_GAIN_PLAN.to_vec();
    let (code, out, err) = run(&args);
    assert_eq!(code, 0, "{err}");
    let answer: serde_json::Value = serde_json::from_str(&out).unwrap();
    let waypoints = answer["waypoints"].as_array().unwrap();
    args.extend(["--output", "nav-msgs-path", "--frame-id", "site/map"]);
    let (code, out, err) = run(&args);
    assert_eq!(code, 0, "{err}");
    let message: serde_json::Value = serde_json::from_str(&out).unwrap();
    check_msg(&message, "nav_msgs/Path", "nav_msgs", "$");
    assert_eq!(message["header"]["frame_id"], "site/map");
    let poses = message["poses"].as_array().unwrap();
    assert_eq!(poses.len(), waypoints.len());
    assert_eq!(poses[1]["pose"]["position"]["x"], waypoints[1]["x"]);
    let mut csv_args = SMALL_GAIN_PLAN.to_vec();
    csv_args.extend(["--output", "csv"]);
    let (code, out, err) = run(&csv_args);
    assert_eq!(code, 0, "{err}");
    let lines: Vec<&str> = out.lines().collect();
    assert_eq!(lines[0], "x,y,yaw_rad,time_s,distance_m,value");
    assert_eq!(lines.len(), waypoints.len() + 1);
    let last: Vec<f64> = lines
        .last()
        .unwrap()
        .split(',')
        .map(|v| v.parse().unwrap())
        .collect();
    assert_eq!(
        last[4],
        waypoints.last().unwrap()["distance_m"].as_f64().unwrap()
    );
    csv_args.extend(["--monte-carlo", "10"]);
    let (code, _, err) = run(&csv_args);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("--monte-carlo"), "{err}");
}
