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
    assert_eq!(waypoints[0]["irs_phases_rad"].as_array().unwrap().len(), 4);
    let distance = body["distance_m"].as_f64().unwrap();
    assert!((body["travel_time_s"].as_f64().unwrap() - distance / 0.5).abs() < 1e-9);
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
    let (code, _, err) = run(&[
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
        "--png",
        file.to_str().unwrap(),
    ]);
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

/// A server that cannot run is a runtime failure (exit 1), not bad input; an invalid scenario
/// file in the preload directory is the operator's input (exit 2, naming the file).
#[test]
fn serve_failures_are_runtime_errors_unless_the_input_is_bad() {
    let taken = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let addr = taken.local_addr().unwrap().to_string();
    let (code, _, err) = run(&["serve", "--bind", &addr, "--scenarios", "no-such-dir"]);
    assert_eq!(code, 1, "{err}");
    assert!(err.contains("--bind"), "{err}");

    let dir = std::env::temp_dir().join(format!("irs-bad-preload-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::write(dir.join("broken.json"), r#"{"room": 1}"#).unwrap();
    let (code, _, err) = run(&[
        "serve",
        "--bind",
        "127.0.0.1:0",
        "--scenarios",
        dir.to_str().unwrap(),
    ]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("broken.json") && err.contains("room"), "{err}");
    std::fs::remove_dir_all(dir).unwrap();
}
