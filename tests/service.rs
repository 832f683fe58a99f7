//! The real server driven over HTTP on an ephemeral loopback port: started in this process
//! through `irs_service::run` (the in-process runtime the binary runs too), or from the built
//! binary where the process itself is under test (SIGTERM, a SIGKILL with `--data-dir`). The
//! contract (openapi.yaml ↔ routes), the paper flow (register, build, plan — checked byte for
//! byte against the CLI), jobs (progress, cancellation, single flight, queue limit) and every
//! error path.

use clap::Parser;
use reqwest::{Client, StatusCode};
use serde_json::{Value, json};
use std::io::{BufRead, BufReader};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

struct Server {
    running: Running,
    base: String,
    client: Client,
}

/// How a test server runs: a task of the test's runtime, or a child process.
enum Running {
    InProcess(tokio::task::JoinHandle<Result<(), irs_service::ServeError>>),
    Binary(Child),
}

impl Drop for Server {
    fn drop(&mut self) {
        match &mut self.running {
            // Dropping `run`'s future cancels the server's jobs.
            Running::InProcess(task) => task.abort(),
            Running::Binary(child) => {
                let _ = child.kill();
                let _ = child.wait();
            }
        }
    }
}

fn root() -> &'static str {
    env!("CARGO_MANIFEST_DIR")
}

/// An empty directory for `--scenarios`: the servers serve the built-in scenarios only.
fn empty_scenarios() -> String {
    let empty = std::env::temp_dir().join(format!("irs-empty-{}", std::process::id()));
    std::fs::create_dir_all(&empty).unwrap();
    empty.to_str().unwrap().to_string()
}

fn client() -> Client {
    Client::builder()
        .timeout(Duration::from_secs(60))
        .build()
        .unwrap()
}

/// `serve`'s flags, parsed as the binary parses them.
#[derive(Parser)]
struct Flags {
    #[command(flatten)]
    serve: irs_service::config::ServeArgs,
}

/// Starts the service in this process (`serve --bind 127.0.0.1:0` with extra flags) through
/// [`irs_service::run`], on the test's runtime.
fn start(extra: &[&str]) -> Server {
    start_with_scenarios(&empty_scenarios(), extra)
}

/// [`start`] with `--scenarios` set to `scenarios`.
fn start_with_scenarios(scenarios: &str, extra: &[&str]) -> Server {
    let flags = Flags::try_parse_from(
        ["serve", "--bind", "127.0.0.1:0", "--scenarios", scenarios]
            .into_iter()
            .chain(extra.iter().copied()),
    )
    .expect("valid flags");
    let listener = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    listener.set_nonblocking(true).unwrap();
    let base = format!("http://{}", listener.local_addr().unwrap());
    let listener = tokio::net::TcpListener::from_std(listener).unwrap();
    let task = tokio::spawn(irs_service::run(
        listener,
        flags.serve,
        std::future::pending(),
    ));
    Server {
        running: Running::InProcess(task),
        base,
        client: client(),
    }
}

/// Starts `irs-planner serve --bind 127.0.0.1:0` with extra flags and waits for its address.
fn start_binary(extra: &[&str]) -> Server {
    let scenarios = empty_scenarios();
    let mut child = Command::new(env!("CARGO_BIN_EXE_irs-planner"))
        .args(["serve", "--bind", "127.0.0.1:0", "--scenarios", &scenarios])
        .args(extra)
        .env("RUST_LOG", "warn")
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .expect("the server starts");
    let mut line = String::new();
    BufReader::new(child.stdout.take().unwrap())
        .read_line(&mut line)
        .unwrap();
    let base = line
        .trim()
        .strip_prefix("listening on ")
        .expect("the server prints its address")
        .to_string();
    Server {
        running: Running::Binary(child),
        base,
        client: client(),
    }
}

impl Server {
    /// The process of a server started by [`start_binary`].
    fn child(&mut self) -> &mut Child {
        match &mut self.running {
            Running::Binary(child) => child,
            Running::InProcess(_) => panic!("an in-process server has no process"),
        }
    }

    /// Sends the server's process SIGTERM, as `docker stop` and Kubernetes do.
    fn sigterm(&mut self) {
        let pid = self.child().id().to_string();
        let sent = Command::new("kill").args(["-TERM", &pid]).status().unwrap();
        assert!(sent.success(), "kill -TERM {pid}: {sent}");
    }
    async fn send(&self, method: &str, path: &str, body: Option<Value>) -> (StatusCode, Value) {
        self.send_as(None, method, path, body).await
    }
    /// A request with `Authorization: Bearer <token>` when a token is given.
    async fn send_as(
        &self,
        token: Option<&str>,
        method: &str,
        path: &str,
        body: Option<Value>,
    ) -> (StatusCode, Value) {
        let url = format!("{}{path}", self.base);
        let req = match method {
            "GET" => self.client.get(url),
            "POST" => self.client.post(url),
            "DELETE" => self.client.delete(url),
            other => self.client.request(other.parse().unwrap(), url),
        };
        let req = match body {
            Some(b) => req
                .header("content-type", "application/json")
                .body(b.to_string()),
            None => req,
        };
        let req = match token {
            Some(t) => req.bearer_auth(t),
            None => req,
        };
        let resp = req.send().await.unwrap();
        let status = resp.status();
        let text = resp.text().await.unwrap();
        (
            status,
            serde_json::from_str(&text).unwrap_or(Value::String(text)),
        )
    }
    async fn get(&self, path: &str) -> (StatusCode, Value) {
        self.send("GET", path, None).await
    }
    async fn post(&self, path: &str, body: Value) -> (StatusCode, Value) {
        self.send("POST", path, Some(body)).await
    }
    async fn scenario_id(&self, name: &str) -> String {
        let (_, list) = self.get("/v1/scenarios").await;
        list["scenarios"]
            .as_array()
            .unwrap()
            .iter()
            .find(|s| s["name"] == name)
            .unwrap()["id"]
            .as_str()
            .unwrap()
            .to_string()
    }
    /// The paper floor's continuous gain map (built while the request waits): its URL.
    async fn paper_gain_map_url(&self) -> String {
        let id = self.scenario_id("paper-single-user").await;
        let (_, map) = self
            .post("/v1/maps", json!({"scenario_id": id, "kind": "gain"}))
            .await;
        format!("{}/v1/maps/{}", self.base, map["map_id"].as_str().unwrap())
    }
    async fn metrics_text(&self) -> String {
        self.client
            .get(format!("{}/metrics", self.base))
            .send()
            .await
            .unwrap()
            .text()
            .await
            .unwrap()
    }
    /// The first metric line that starts with `needle` (a name with its labels).
    async fn metric(&self, needle: &str) -> f64 {
        self.metrics_text()
            .await
            .lines()
            .find(|l| l.starts_with(needle))
            .and_then(|l| l.rsplit(' ').next())
            .map_or(0.0, |v| v.parse().unwrap())
    }
    /// The sum of a metric over all its labels (`name{…} v` and `name v` lines).
    async fn metric_total(&self, name: &str) -> f64 {
        self.metrics_text()
            .await
            .lines()
            .filter(|l| {
                l.strip_prefix(name)
                    .is_some_and(|rest| rest.starts_with('{') || rest.starts_with(' '))
            })
            .filter_map(|l| l.rsplit(' ').next()?.parse::<f64>().ok())
            .sum()
    }
    async fn wait_job(&self, job_id: &str) -> Value {
        self.wait_job_as(None, job_id).await
    }
    /// [`Server::wait_job`] for the owner of `token` (a job is its owners' only).
    async fn wait_job_as(&self, token: Option<&str>, job_id: &str) -> Value {
        let deadline = Instant::now() + Duration::from_secs(120);
        loop {
            let (_, job) = self
                .send_as(token, "GET", &format!("/v1/jobs/{job_id}"), None)
                .await;
            if ["done", "failed", "cancelled"].contains(&job["state"].as_str().unwrap()) {
                return job;
            }
            assert!(Instant::now() < deadline, "job {job_id} did not finish");
            tokio::time::sleep(Duration::from_millis(20)).await;
        }
    }
}

/// A scenario document from scenarios/, optionally edited.
fn scenario(file: &str, edit: impl FnOnce(&mut Value)) -> Value {
    let mut v: Value = serde_json::from_str(
        &std::fs::read_to_string(format!("{}/scenarios/{file}", root())).unwrap(),
    )
    .unwrap();
    edit(&mut v);
    v
}

fn problem(status: StatusCode, body: &Value, expected: StatusCode, code: &str) {
    // A failure names the answer's first characters (a map body is megabytes).
    let body_start: String = body.to_string().chars().take(300).collect();
    assert_eq!(status, expected, "{body_start}");
    assert_eq!(body["code"], code, "{body_start}");
    assert_eq!(body["status"], expected.as_u16(), "{body_start}");
    assert!(body["type"].as_str().unwrap().ends_with(code));
    assert!(!body["detail"].as_str().unwrap().is_empty());
}

/// A scenario's `route_graph`: a Nav2 graph of two nodes and a two-way lane between them.
fn two_node_graph(a: [f64; 2], b: [f64; 2]) -> Value {
    let node = |id: u32, p: [f64; 2]| {
        json!({"type": "Feature", "properties": {"id": id, "frame": "map"},
               "geometry": {"type": "Point", "coordinates": p}})
    };
    let edge = |id: u32, start: u32, end: u32| {
        json!({"type": "Feature", "properties": {"id": id, "startid": start, "endid": end},
               "geometry": {"type": "MultiLineString", "coordinates": []}})
    };
    json!({"format": "nav2_geojson", "graph": {"type": "FeatureCollection",
        "features": [node(0, a), node(1, b), edge(2, 0, 1), edge(3, 1, 0)]}})
}

/// The (method, path) pairs of openapi.yaml, read from its `paths:` section.
fn documented_routes() -> Vec<(String, String)> {
    let text = std::fs::read_to_string(format!("{}/openapi.yaml", root())).unwrap();
    let mut in_paths = false;
    let mut path = String::new();
    let mut routes = Vec::new();
    for line in text.lines() {
        if !line.starts_with(' ') {
            in_paths = line == "paths:";
            continue;
        }
        if !in_paths {
            continue;
        }
        if let Some(p) = line.strip_prefix("  /") {
            path = format!("/{}", p.trim_end_matches(':'));
        } else if let Some(m) = line.strip_prefix("    ") {
            let m = m.trim_end_matches(':');
            if ["get", "post", "put", "delete", "patch"].contains(&m) {
                routes.push((m.to_string(), path.clone()));
            }
        }
    }
    routes.sort();
    routes
}

/// The contract states the number grammar of query strings that are not plain numbers as regex
/// patterns; they are exactly the grammar the server's scanner implements
/// (`input::NUMBER_PATTERN`), so the two cannot drift.
#[test]
fn openapi_query_patterns_are_the_servers_number_grammar() {
    let text = std::fs::read_to_string(format!("{}/openapi.yaml", root())).unwrap();
    let number = irs_model::input::NUMBER_PATTERN;
    let expected = [
        format!("'^{number}$'"),
        format!("'^(max|{number})$'"),
        format!("'^{number},{number}$'"),
    ];
    let patterns: Vec<&str> = text
        .lines()
        .filter_map(|line| line.split("pattern: ").nth(1))
        .map(|rest| rest.split(" }").next().unwrap())
        // A listing's cursor is an opaque key and a frame id a name, not numbers.
        .filter(|pattern| *pattern != "'^[A-Za-z0-9]{1,128}$'")
        .filter(|pattern| *pattern != "\"^[A-Za-z0-9_][A-Za-z0-9_/]*$\"")
        .collect();
    // Plain numbers are `type: number` (generated clients take them as numbers); what else a
    // query may hold is a string with its pattern: a picture's threshold ("max" or a number),
    // its start and goal ("x,y").
    assert_eq!(patterns.len(), 3, "threshold or max, start, goal");
    for pattern in patterns {
        assert!(expected.iter().any(|e| e == pattern), "{pattern}");
    }
}

#[tokio::test]
async fn openapi_paths_are_exactly_the_served_routes() {
    let mut served: Vec<(String, String)> = irs_service::http::route_table()
        .into_iter()
        .flat_map(|(path, methods, _)| {
            methods
                .iter()
                .map(move |m| (m.to_string(), path.to_string()))
        })
        .collect();
    served.sort();
    assert_eq!(served, documented_routes());
    // And the running server answers each of them (not with route_not_found / 405).
    let server = start(&[]);
    for (method, path) in documented_routes() {
        let concrete = path
            .replace("{scenario_id}", "x")
            .replace("{map_id}", "x")
            .replace("{job_id}", "x");
        let body = (method == "post").then(|| json!({}));
        let (status, body) = server.send(&method.to_uppercase(), &concrete, body).await;
        assert_ne!(status, StatusCode::METHOD_NOT_ALLOWED, "{method} {path}");
        assert_ne!(body["code"], "route_not_found", "{method} {path}");
    }
}

#[tokio::test]
async fn paper_flow_matches_the_cli_byte_for_byte() {
    let server = start(&[]);
    // Registering by content: a new document is 201, the same one again 200 with the same id.
    let doc = scenario("paper-single-user.json", |v| {
        v["name"] = "paper-single-user-copy".into()
    });
    let (s1, first) = server.post("/v1/scenarios", doc.clone()).await;
    let (s2, second) = server.post("/v1/scenarios", doc).await;
    assert_eq!((s1, s2), (StatusCode::CREATED, StatusCode::OK));
    assert_eq!(first["id"], second["id"]);
    let (status, got) = server
        .get(&format!("/v1/scenarios/{}", first["id"].as_str().unwrap()))
        .await;
    assert_eq!(status, StatusCode::OK);
    assert_eq!(got["scenario"]["irs"]["sub_pitch_m"], 0.0075);

    let id = server.scenario_id("paper-single-user").await;
    let (status, map) = server
        .post(
            "/v1/maps",
            json!({"scenario_id": id, "kind": "gain", "phases": "continuous"}),
        )
        .await;
    assert_eq!(status, StatusCode::OK, "{map}");
    let map_id = map["map_id"].as_str().unwrap();
    let (status, body) = server.get(&format!("/v1/maps/{map_id}")).await;
    assert_eq!(status, StatusCode::OK);
    assert_eq!(body["values"].as_array().unwrap().len(), 41);
    let (_, cov) = server
        .get(&format!("/v1/maps/{map_id}/coverage?threshold=-60"))
        .await;
    assert!(cov["coverage"].as_f64().unwrap() > 0.0 && cov["coverage"].as_f64().unwrap() < 1.0);

    // The path answer equals the CLI's output exactly, and the request id is echoed.
    let request = json!({"map_id": map_id, "start": [-10, 0], "goal": [10, 0], "threshold": "max"});
    let resp = server
        .client
        .post(format!("{}/v1/paths", server.base))
        .header("content-type", "application/json")
        .header("x-request-id", "test-123")
        .body(request.to_string())
        .send()
        .await
        .unwrap();
    assert_eq!(resp.headers()["x-request-id"], "test-123");
    let api_body = resp.text().await.unwrap();
    let cli = Command::new(env!("CARGO_BIN_EXE_irs-planner"))
        .args([
            "plan",
            "--scenario",
            "scenarios/paper-single-user.json",
            "--kind",
            "gain",
            "--start=-10,0",
            "--goal",
            "10,0",
            "--max-threshold",
            "--quiet",
        ])
        .current_dir(root())
        .output()
        .unwrap();
    // Identical but for the time each took (the last field).
    let untimed = |body: &str| body.rsplit_once(",\"took_ms\":").unwrap().0.to_string();
    let cli_body = String::from_utf8(cli.stdout).unwrap();
    assert_eq!(untimed(&api_body), untimed(cli_body.trim_end()));
    let path: Value = serde_json::from_str(&api_body).unwrap();
    assert!(path["took_ms"].as_f64().unwrap() >= 0.0);
    assert!((path["max_feasible_threshold"].as_f64().unwrap() - -59.6).abs() < 0.3);

    // Phases are written to 1e-4 rad by default; `full` keeps every bit, and the two agree to
    // half a step. An unknown precision is refused, naming the field.
    let phases = |answer: &Value| -> Vec<f64> {
        answer["waypoints"]
            .as_array()
            .unwrap()
            .iter()
            .flat_map(|w| w["irs_phases_rad"][0].as_array().unwrap().clone())
            .map(|t| t.as_f64().unwrap())
            .collect()
    };
    let mut full_request = request.clone();
    full_request["phase_precision"] = "full".into();
    let (status, full) = server.post("/v1/paths", full_request.clone()).await;
    assert_eq!(status, StatusCode::OK, "{full}");
    let (rounded, exact) = (phases(&path), phases(&full));
    assert_eq!(rounded.len(), exact.len());
    assert!(!rounded.is_empty() && rounded.len() % 60 == 0);
    for (r, e) in rounded.iter().zip(&exact) {
        let error = (r - e).abs();
        assert!(
            error.min(std::f64::consts::TAU - error) <= 5e-5 + 1e-12,
            "{r} vs {e}"
        );
        assert_eq!(*r, (r * 1e4).round() / 1e4, "{r} has more than 4 decimals");
    }
    assert!(exact.iter().any(|e| *e != (e * 1e4).round() / 1e4));
    let full_bytes = serde_json::to_string(&full).unwrap().len();
    assert!(
        api_body.len() * 2 < full_bytes,
        "rounded {} B vs full {full_bytes} B",
        api_body.len()
    );
    full_request["phase_precision"] = "1e-5".into();
    refused_naming(&server, full_request, "phase_precision").await;

    // Poses in the frame the request names (`map` by default), a ROS tf2 frame id or a 422.
    assert_eq!(path["frame_id"], "map");
    let goal = path["waypoints"]
        .as_array()
        .unwrap()
        .last()
        .unwrap()
        .clone();
    let along = goal["distance_m"].as_f64().unwrap();
    assert!((along - path["distance_m"].as_f64().unwrap()).abs() < 1e-9);
    assert!(goal["yaw_rad"].is_number() && goal["time_s"].is_number());
    let mut framed = request.clone();
    framed["frame_id"] = "site_a/map".into();
    let (status, in_frame) = server.post("/v1/paths", framed.clone()).await;
    assert_eq!(status, StatusCode::OK, "{in_frame}");
    assert_eq!(in_frame["frame_id"], "site_a/map");
    assert_eq!(in_frame["waypoints"], path["waypoints"]);
    for bad in ["/map", "", "map frame"] {
        framed["frame_id"] = bad.into();
        refused_naming(&server, framed.clone(), "frame_id").await;
    }
    // Thresholds in the operator's units (docs/model.md §3.1): 20 dBm of transmit power and no
    // antenna gains, so a received-power threshold is the gain threshold + 20 and selects the
    // same path; the answer labels its unit, and the answer cache keeps the two apart.
    let widest_db = path["max_feasible_threshold"].as_f64().unwrap();
    let mut in_dbm = request.clone();
    in_dbm["unit"] = "dbm".into();
    in_dbm["threshold"] = (widest_db + 20.0 - 0.5).into();
    let (status, dbm) = server.post("/v1/paths", in_dbm.clone()).await;
    assert_eq!(status, StatusCode::OK, "{dbm}");
    assert_eq!(
        (dbm["unit"].as_str(), path["unit"].as_str()),
        (Some("dBm"), Some("dB"))
    );
    let widest_dbm = dbm["max_feasible_threshold"].as_f64().unwrap();
    assert!(
        (widest_dbm - (widest_db + 20.0)).abs() < 1e-9,
        "{widest_dbm}"
    );
    let mut in_db = request.clone();
    in_db["threshold"] = (widest_db - 0.5).into();
    let (_, db) = server.post("/v1/paths", in_db).await;
    let cells = |answer: &Value| -> Vec<(Value, Value, f64)> {
        answer["waypoints"]
            .as_array()
            .unwrap()
            .iter()
            .map(|w| (w["i"].clone(), w["j"].clone(), w["value"].as_f64().unwrap()))
            .collect()
    };
    let (a, b) = (cells(&db), cells(&dbm));
    assert_eq!(a.len(), b.len());
    for ((ia, ja, va), (ib, jb, vb)) in a.iter().zip(&b) {
        assert_eq!((ia, ja), (ib, jb));
        assert!((vb - (va + 20.0)).abs() < 1e-9);
    }
    // The same threshold with straight segments: shorter, its own entry in the answer cache.
    let mut any_angle = request.clone();
    any_angle["threshold"] = (widest_db - 0.5).into();
    any_angle["path_shape"] = "any_angle".into();
    let (status, any) = server.post("/v1/paths", any_angle.clone()).await;
    assert_eq!(status, StatusCode::OK, "{any}");
    assert_eq!(
        (any["path_shape"].as_str(), db["path_shape"].as_str()),
        (Some("any_angle"), Some("grid"))
    );
    let (a, g) = (
        any["distance_m"].as_f64().unwrap(),
        db["distance_m"].as_f64().unwrap(),
    );
    assert!(a < g, "any-angle {a} m vs grid {g} m");
    let vertices = any["vertices"].as_array().unwrap();
    assert!(vertices.len() >= 2 && vertices.len() < db["vertices"].as_array().unwrap().len());
    any_angle["path_shape"] = "diagonal".into();
    refused_naming(&server, any_angle, "path_shape").await;
    for bad in [-1.0, 51.0] {
        let mut far = request.clone();
        far["tolerance_m"] = bad.into();
        refused_naming(&server, far, "tolerance_m").await;
    }
    let (status, cov_snr) = server
        .get(&format!(
            "/v1/maps/{map_id}/coverage?threshold=50&unit=snr_db"
        ))
        .await;
    assert_eq!(status, StatusCode::OK, "{cov_snr}");
    assert_eq!(cov_snr["unit"], "dB SNR");
    // −60 dB of gain is 50 dB of SNR here (20 dBm, σ² = −90 dBm).
    assert_eq!(cov_snr["covered_cells"], cov["covered_cells"]);
    // Throughput needs a bandwidth the scenario does not state; unknown units are refused.
    in_dbm["unit"] = "mbps".into();
    refused_naming(&server, in_dbm.clone(), "unit").await;
    in_dbm["unit"] = "dBm".into();
    let (status, body) = server.post("/v1/paths", in_dbm).await;
    assert_eq!(status, StatusCode::UNPROCESSABLE_ENTITY, "{body}");
    let (status, body) = server
        .get(&format!("/v1/maps/{map_id}/values.npy?unit=mbps"))
        .await;
    problem(
        status,
        &body,
        StatusCode::UNPROCESSABLE_ENTITY,
        "invalid_field",
    );
    assert_eq!(body["field"], "unit");
    // The same path as a ROS nav_msgs/Path or as CSV, by Accept (no Monte Carlo report there).
    let as_media = |accept: &'static str, body: Value| {
        let request = server
            .client
            .post(format!("{}/v1/paths", server.base))
            .header("accept", accept)
            .json(&body);
        async move {
            let resp = request.send().await.unwrap();
            let media = resp.headers()["content-type"].to_str().unwrap().to_string();
            (resp.status(), media, resp.text().await.unwrap())
        }
    };
    let waypoints = path["waypoints"].as_array().unwrap();
    let (status, media, text) =
        as_media("application/vnd.ros.nav-msgs.path+json", request.clone()).await;
    assert_eq!(
        (status, media.as_str()),
        (StatusCode::OK, "application/vnd.ros.nav-msgs.path+json")
    );
    let message: Value = serde_json::from_str(&text).unwrap();
    assert_eq!(message["header"]["frame_id"], "map");
    assert_eq!(message["poses"].as_array().unwrap().len(), waypoints.len());
    let (status, media, text) = as_media("text/csv, application/json;q=0.5", request.clone()).await;
    assert_eq!(
        (status, media.as_str()),
        (StatusCode::OK, "text/csv; charset=utf-8")
    );
    assert_eq!(text.lines().count(), waypoints.len() + 1);
    let mut checked = request.clone();
    checked["monte_carlo_draws"] = 10.into();
    let (status, _, text) = as_media("text/csv", checked).await;
    assert_eq!(status, StatusCode::UNPROCESSABLE_ENTITY, "{text}");
    assert!(text.contains("monte_carlo_draws"), "{text}");

    // As 16-bit codes: the same phases to π/2¹⁶, in at most a third of the full answer's bytes,
    // and no radians beside them; a precision applies to radians only.
    let mut codes_request = request.clone();
    codes_request["phase_format"] = "codes".into();
    let (status, codes) = server.post("/v1/paths", codes_request.clone()).await;
    assert_eq!(status, StatusCode::OK, "{codes}");
    let decoded = decode_codes(&codes);
    assert_eq!(decoded.len(), exact.len());
    for (d, e) in decoded.iter().zip(&exact) {
        let error = (d - e).abs();
        assert!(
            error.min(std::f64::consts::TAU - error) <= std::f64::consts::PI / 65536.0 + 1e-12,
            "{d} vs {e}"
        );
    }
    assert!(codes["waypoints"][0].get("irs_phases_rad").is_none());
    let codes_bytes = serde_json::to_string(&codes).unwrap().len();
    assert!(
        codes_bytes * 3 <= full_bytes,
        "codes {codes_bytes} B vs full {full_bytes} B"
    );
    codes_request["phase_precision"] = "1e-2".into();
    refused_naming(&server, codes_request, "phase_precision").await;

    // A sweep over thresholds, defined by the map key instead of the id.
    let (status, sweep) = server
        .post("/v1/sweeps", json!({"map": {"scenario_id": id, "kind": "gain"}, "start": [-10, 0], "goal": [10, 0], "thresholds": [-65, -62, -59]}))
        .await;
    assert_eq!(status, StatusCode::OK, "{sweep}");
    let feasible: Vec<bool> = sweep["points"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| p["feasible"].as_bool().unwrap())
        .collect();
    assert_eq!(feasible, [true, true, false]);
}

#[tokio::test]
async fn rate_map_job_reports_progress_and_serves_paths_with_powers() {
    let server = start(&["--workers", "1"]);
    let id = server.scenario_id("paper-multi-user").await;
    let (status, job) = server
        .post(
            "/v1/maps",
            json!({"scenario_id": id, "kind": "rate", "access": "noma"}),
        )
        .await;
    assert_eq!(status, StatusCode::ACCEPTED, "{job}");
    let job_id = job["job_id"].as_str().unwrap().to_string();
    // Poll and record progress until done.
    let mut seen = Vec::new();
    let deadline = Instant::now() + Duration::from_secs(120);
    loop {
        let (_, j) = server.get(&format!("/v1/jobs/{job_id}")).await;
        seen.push((
            j["cells_done"].as_u64().unwrap(),
            j["cells_total"].as_u64().unwrap(),
        ));
        if j["state"] == "done" {
            break;
        }
        assert!(Instant::now() < deadline);
        tokio::time::sleep(Duration::from_millis(10)).await;
    }
    assert!(
        seen.iter().any(|&(d, t)| d > 0 && d < t),
        "no intermediate progress seen: {seen:?}"
    );
    assert!(
        seen.windows(2).all(|w| w[0].0 <= w[1].0),
        "progress went backwards"
    );
    let (status, path) = server
        .post(
            "/v1/paths",
            json!({"map_id": job["map_id"], "start": [-10, 0], "goal": [10, 0], "threshold": 6.0}),
        )
        .await;
    assert_eq!(status, StatusCode::OK, "{path}");
    let wp = &path["waypoints"][0];
    assert_eq!(wp["irs_phases_rad"][0].as_array().unwrap().len(), 60);
    assert_eq!(wp["irs_phases_rad"].as_array().unwrap().len(), 1);
    assert_eq!(wp["power_w"].as_array().unwrap().len(), 2);
    assert_eq!(wp["decoding_order"].as_array().unwrap().len(), 2);
    // A rate map keeps its phases as 16-bit codes: written as codes they decode to exactly the
    // phases written in full.
    let query = |format: &str, precision: Option<&str>| {
        let mut q = json!({"map_id": job["map_id"], "start": [-10, 0], "goal": [10, 0], "threshold": 6.0, "phase_format": format});
        if let Some(p) = precision {
            q["phase_precision"] = p.into();
        }
        q
    };
    let (_, codes) = server.post("/v1/paths", query("codes", None)).await;
    let (_, full) = server
        .post("/v1/paths", query("radians", Some("full")))
        .await;
    let full_phases: Vec<f64> = full["waypoints"]
        .as_array()
        .unwrap()
        .iter()
        .flat_map(|w| w["irs_phases_rad"][0].as_array().unwrap().clone())
        .map(|t| t.as_f64().unwrap())
        .collect();
    assert_eq!(decode_codes(&codes), full_phases);
    // A rate map holds rates: received power or SNR is refused, naming `unit`.
    let mut in_dbm = query("radians", None);
    in_dbm["unit"] = "dbm".into();
    refused_naming(&server, in_dbm, "unit").await;
    let (_, body) = server
        .get(&format!("/v1/maps/{}", job["map_id"].as_str().unwrap()))
        .await;
    assert!(body["certificate"]["max_gap"].as_f64().unwrap() <= 0.05);
}

/// A path request answered 422 `invalid_field`, naming `field`.
async fn refused_naming(server: &Server, request: Value, field: &str) {
    let (status, body) = server.post("/v1/paths", request).await;
    problem(
        status,
        &body,
        StatusCode::UNPROCESSABLE_ENTITY,
        "invalid_field",
    );
    assert_eq!(body["field"], field, "{body}");
}

/// Every waypoint's first-surface phases of a `phase_format: codes` answer, decoded
/// (little-endian 16-bit codes in base64, θ = 2π·c/65536).
fn decode_codes(answer: &Value) -> Vec<f64> {
    use base64::Engine;
    answer["waypoints"]
        .as_array()
        .unwrap()
        .iter()
        .flat_map(|w| {
            let text = w["irs_phase_codes"][0].as_str().unwrap();
            base64::engine::general_purpose::STANDARD
                .decode(text)
                .unwrap()
                .chunks_exact(2)
                .map(|c| {
                    f64::from(u16::from_le_bytes([c[0], c[1]])) * std::f64::consts::TAU / 65536.0
                })
                .collect::<Vec<_>>()
        })
        .collect()
}

/// A long build: the paper's multi-user floor at 0.2 m (101 × 101 cells).
fn long_rate_request(server_scenario: Value, access: &str) -> Value {
    json!({"scenario": server_scenario, "kind": "rate", "access": access})
}

fn fine_multi_user(name: &str) -> Value {
    scenario("paper-multi-user.json", |v| {
        v["grid"]["resolution_m"] = 0.2.into();
        v["name"] = name.into();
    })
}

#[tokio::test]
async fn cancelling_a_job_stops_the_build() {
    let server = start(&["--workers", "1"]);
    let (status, job) = server
        .post(
            "/v1/maps",
            long_rate_request(fine_multi_user("fine"), "noma"),
        )
        .await;
    assert_eq!(status, StatusCode::ACCEPTED, "{job}");
    let job_id = job["job_id"].as_str().unwrap();
    tokio::time::sleep(Duration::from_millis(300)).await;
    let (status, _) = server
        .send("DELETE", &format!("/v1/jobs/{job_id}"), None)
        .await;
    assert_eq!(status, StatusCode::ACCEPTED);
    let started = Instant::now();
    let finished = server.wait_job(job_id).await;
    assert_eq!(finished["state"], "cancelled");
    assert!(
        started.elapsed() < Duration::from_secs(5),
        "cancellation took {:?}",
        started.elapsed()
    );
    assert!(finished["cells_done"].as_u64().unwrap() < finished["cells_total"].as_u64().unwrap());
    let (status, body) = server
        .send("DELETE", &format!("/v1/jobs/{job_id}"), None)
        .await;
    problem(status, &body, StatusCode::CONFLICT, "job_finished");
    let (status, body) = server
        .get(&format!("/v1/maps/{}", job["map_id"].as_str().unwrap()))
        .await;
    problem(status, &body, StatusCode::NOT_FOUND, "not_found");
}

#[tokio::test]
async fn concurrent_requests_for_one_map_start_one_build() {
    let server = start(&[]);
    let id = server.scenario_id("paper-multi-user").await;
    let before = server.metric("irs_map_builds_total{kind=\"rate\"}").await;
    let request = json!({"scenario_id": id, "kind": "rate", "access": "oma"});
    let answers = futures_join_all(&server, &vec![request.clone(); 8]).await;
    let job_ids: std::collections::HashSet<String> = answers
        .iter()
        .map(|(_, b)| b["job_id"].as_str().unwrap().to_string())
        .collect();
    assert_eq!(job_ids.len(), 1, "{answers:?}");
    server.wait_job(job_ids.iter().next().unwrap()).await;
    // Once built, the map answers at once.
    let (status, _) = server.post("/v1/maps", request).await;
    assert_eq!(status, StatusCode::OK);
    assert_eq!(
        server.metric("irs_map_builds_total{kind=\"rate\"}").await - before,
        1.0
    );
    assert!(
        server
            .metric("irs_map_cache_requests_total{outcome=\"hit\"}")
            .await
            >= 1.0
    );
}

/// POSTs every request to /v1/maps at once; the answers in request order.
async fn futures_join_all(server: &Server, requests: &[Value]) -> Vec<(StatusCode, Value)> {
    let mut handles = Vec::new();
    for request in requests {
        let (client, url, body) = (
            server.client.clone(),
            format!("{}/v1/maps", server.base),
            request.to_string(),
        );
        handles.push(tokio::spawn(async move {
            let resp = client
                .post(url)
                .header("content-type", "application/json")
                .body(body)
                .send()
                .await
                .unwrap();
            let status = resp.status();
            (status, resp.json::<Value>().await.unwrap())
        }));
    }
    let mut out = Vec::new();
    for h in handles {
        out.push(h.await.unwrap());
    }
    out
}

#[tokio::test]
async fn a_full_queue_answers_503_with_retry_after() {
    let server = start(&["--workers", "1", "--queue", "1"]);
    let mut jobs = Vec::new();
    for name in ["q1", "q2"] {
        let (status, job) = server
            .post("/v1/maps", long_rate_request(fine_multi_user(name), "noma"))
            .await;
        assert_eq!(status, StatusCode::ACCEPTED, "{job}");
        jobs.push(job["job_id"].as_str().unwrap().to_string());
    }
    let resp = server
        .client
        .post(format!("{}/v1/maps", server.base))
        .header("content-type", "application/json")
        .body(long_rate_request(fine_multi_user("q3"), "noma").to_string())
        .send()
        .await
        .unwrap();
    assert_eq!(resp.status(), StatusCode::SERVICE_UNAVAILABLE);
    assert!(resp.headers().contains_key("retry-after"));
    assert_eq!(resp.headers()["content-type"], "application/problem+json");
    let body: Value = resp.json().await.unwrap();
    assert_eq!(body["code"], "queue_full");
    assert_eq!(body["limit"], 1);
    for job in jobs {
        server
            .send("DELETE", &format!("/v1/jobs/{job}"), None)
            .await;
        assert_eq!(server.wait_job(&job).await["state"], "cancelled");
    }
}

/// Registration has its own body limit (`--max-scenario-body-kb`), where floor plans travel:
/// a body between the two limits registers, and is refused everywhere else, declared or
/// streamed; over the larger one registration is refused too, each 413 naming its limit.
#[tokio::test]
async fn scenarios_have_a_larger_body_limit_for_floor_plans() {
    let server = start(&["--max-body-kb", "16", "--max-scenario-body-kb", "64"]);
    // The document padded with whitespace to the size wanted (still the same document).
    let padded = |bytes: usize| {
        let doc = scenario("small-test.json", |v| v["name"] = "padded".into()).to_string();
        format!("{}{}", " ".repeat(bytes - doc.len()), doc)
    };
    let send = |path: &'static str, body: String, chunked: bool| {
        let (client, base) = (server.client.clone(), server.base.clone());
        async move {
            if !chunked {
                let response = client
                    .post(format!("{base}{path}"))
                    .header("content-type", "application/json")
                    .body(body)
                    .send()
                    .await
                    .unwrap();
                let status = response.status();
                return (status, response.json::<Value>().await.unwrap());
            }
            // Streamed: no length declared, the body in chunks.
            use tokio::io::{AsyncReadExt, AsyncWriteExt};
            let mut stream = tokio::net::TcpStream::connect(base.trim_start_matches("http://"))
                .await
                .unwrap();
            let head = format!(
                "POST {path} HTTP/1.1\r\nhost: x\r\ncontent-type: application/json\r\n\
                 transfer-encoding: chunked\r\nconnection: close\r\n\r\n"
            );
            stream.write_all(head.as_bytes()).await.unwrap();
            for chunk in body.as_bytes().chunks(4096) {
                let framed = [format!("{:x}\r\n", chunk.len()).as_bytes(), chunk, b"\r\n"].concat();
                if stream.write_all(&framed).await.is_err() {
                    break; // answered and closed before the end
                }
            }
            let _ = stream.write_all(b"0\r\n\r\n").await;
            let mut answer = Vec::new();
            let _ = stream.read_to_end(&mut answer).await;
            let text = String::from_utf8_lossy(&answer);
            let status: u16 = text[9..12].parse().unwrap();
            let json = text
                .find("\r\n\r\n")
                .map(|at| &text[at + 4..])
                .and_then(|rest| {
                    // The body may come chunked: the JSON object between the first { and last }.
                    let (a, b) = (rest.find('{')?, rest.rfind('}')?);
                    serde_json::from_str(&rest[a..=b]).ok()
                })
                .unwrap_or(Value::Null);
            (StatusCode::from_u16(status).unwrap(), json)
        }
    };
    let (s, body) = send("/v1/scenarios", padded(40_000), false).await;
    assert!(s.is_success(), "{s} {body}");
    let (s, body) = send("/v1/scenarios", padded(40_000), true).await;
    assert!(s.is_success(), "streamed: {s} {body}");
    for chunked in [false, true] {
        let (s, body) = send("/v1/maps", padded(40_000), chunked).await;
        problem(s, &body, StatusCode::PAYLOAD_TOO_LARGE, "body_too_large");
        assert_eq!(body["limit"], 16 * 1024);
        let (s, body) = send("/v1/scenarios", padded(70_000), chunked).await;
        problem(s, &body, StatusCode::PAYLOAD_TOO_LARGE, "body_too_large");
        assert_eq!(body["limit"], 64 * 1024);
    }
}

#[tokio::test]
async fn every_error_is_a_problem_naming_its_field() {
    let server = start(&["--max-body-kb", "16", "--max-scenarios", "4"]);
    let id = server.scenario_id("small-test").await;
    let raw = |body: &'static str, content_type: &'static str| {
        let (client, url) = (server.client.clone(), format!("{}/v1/paths", server.base));
        async move {
            let resp = client
                .post(url)
                .header("content-type", content_type)
                .body(body)
                .send()
                .await
                .unwrap();
            assert_eq!(resp.headers()["content-type"], "application/problem+json");
            (resp.status(), resp.json::<Value>().await.unwrap())
        }
    };
    let (s, b) = raw("{not json", "application/json").await;
    problem(s, &b, StatusCode::BAD_REQUEST, "malformed_json");
    let (s, b) = raw("{}", "text/plain").await;
    problem(
        s,
        &b,
        StatusCode::UNSUPPORTED_MEDIA_TYPE,
        "unsupported_media_type",
    );
    // A body without a content type is not guessed at.
    let resp = server
        .client
        .post(format!("{}/v1/paths", server.base))
        .body("{}")
        .send()
        .await
        .unwrap();
    assert_eq!(resp.status(), StatusCode::UNSUPPORTED_MEDIA_TYPE);
    // An array of the wrong length is a field error (422), not a syntax error.
    let (s, b) = raw(
        r#"{"map_id": "x", "start": [1, 2, 3], "goal": [1, 2], "threshold": 0}"#,
        "application/json",
    )
    .await;
    problem(s, &b, StatusCode::UNPROCESSABLE_ENTITY, "invalid_field");
    assert_eq!(b["field"], "start");
    let big = format!("{{\"start\": [{}0]}}", "0,".repeat(10_000));
    let resp = server
        .client
        .post(format!("{}/v1/paths", server.base))
        .header("content-type", "application/json")
        .body(big)
        .send()
        .await
        .unwrap();
    let status = resp.status();
    let body: Value = resp.json().await.unwrap();
    problem(
        status,
        &body,
        StatusCode::PAYLOAD_TOO_LARGE,
        "body_too_large",
    );
    assert_eq!(body["limit"], 16384);

    let map = json!({"scenario_id": id, "kind": "gain"});
    let cases: Vec<(&str, Value, StatusCode, &str, Option<&str>)> = vec![
        (
            "/v1/paths",
            json!({"map": map, "start": [1, 1], "goal": [2, 2], "threshold": 0, "bogus": 1}),
            StatusCode::UNPROCESSABLE_ENTITY,
            "invalid_field",
            Some("bogus"),
        ),
        (
            "/v1/paths",
            json!({"map": map, "start": [1, 1], "goal": [2, 2], "threshold": "most"}),
            StatusCode::UNPROCESSABLE_ENTITY,
            "invalid_field",
            Some("threshold"),
        ),
        (
            "/v1/paths",
            json!({"map": map, "start": [99, 1], "goal": [2, 2], "threshold": -80}),
            StatusCode::UNPROCESSABLE_ENTITY,
            "invalid_field",
            Some("start"),
        ),
        (
            "/v1/paths",
            json!({"map_id": "nope", "start": [1, 1], "goal": [2, 2], "threshold": 0}),
            StatusCode::NOT_FOUND,
            "not_found",
            None,
        ),
        (
            "/v1/paths",
            json!({"start": [1, 1], "goal": [2, 2], "threshold": 0}),
            StatusCode::UNPROCESSABLE_ENTITY,
            "invalid_field",
            Some("map_id"),
        ),
        (
            "/v1/paths",
            json!({"map": {"scenario_id": id, "kind": "gain", "access": "oma"}, "start": [1, 1], "goal": [2, 2], "threshold": 0}),
            StatusCode::UNPROCESSABLE_ENTITY,
            "invalid_field",
            Some("map.access"),
        ),
        (
            "/v1/paths",
            json!({"map": {"scenario_id": "nope", "kind": "gain"}, "start": [1, 1], "goal": [2, 2], "threshold": 0}),
            StatusCode::NOT_FOUND,
            "not_found",
            Some("map.scenario_id"),
        ),
        (
            "/v1/paths",
            json!({"map": map, "start": [1, 1], "goal": [2, 2], "threshold": 0, "monte_carlo_draws": 10_000_000}),
            StatusCode::UNPROCESSABLE_ENTITY,
            "limit_exceeded",
            Some("monte_carlo_draws"),
        ),
        (
            "/v1/sweeps",
            json!({"map": map, "start": [1, 1], "goal": [2, 2], "thresholds": vec![0.0; 1001]}),
            StatusCode::UNPROCESSABLE_ENTITY,
            "limit_exceeded",
            Some("thresholds"),
        ),
        (
            "/v1/maps",
            json!({"scenario_id": id, "kind": "rate", "phases": 0}),
            StatusCode::UNPROCESSABLE_ENTITY,
            "invalid_field",
            Some("phases"),
        ),
        (
            "/v1/maps",
            json!({"scenario": scenario("small-test.json", |v| v["grid"]["resolution_m"] = 0.0001.into()), "kind": "gain"}),
            StatusCode::UNPROCESSABLE_ENTITY,
            "invalid_scenario",
            Some("scenario.grid.resolution_m"),
        ),
        (
            "/v1/maps",
            json!({"scenario": scenario("paper-multi-user.json", |v| v["grid"]["resolution_m"] = 0.05.into()), "kind": "rate"}),
            StatusCode::UNPROCESSABLE_ENTITY,
            "limit_exceeded",
            Some("kind"),
        ),
        (
            "/v1/scenarios",
            scenario("small-test.json", |v| {
                v["ap"]["position"] = json!([3.0, 2.0, 1.0])
            }),
            StatusCode::UNPROCESSABLE_ENTITY,
            "invalid_scenario",
            Some("ap.position"),
        ),
    ];
    for (path, body, status, code, field) in cases {
        let (s, b) = server.post(path, body.clone()).await;
        problem(s, &b, status, code);
        if let Some(field) = field {
            assert_eq!(b["field"], field, "{path} {body}: {b}");
        }
    }
    // The registry limit (4, three of them built in): one more is fine. The next one evicts the
    // least recently used API scenario with the maps built from it (a cached map no longer
    // pins its scenario, so nobody can lock the registry with maps).
    let (s, a) = server
        .post(
            "/v1/scenarios",
            scenario("small-test.json", |v| v["name"] = "a".into()),
        )
        .await;
    assert_eq!(s, StatusCode::CREATED);
    let a_id = a["id"].as_str().unwrap().to_string();
    let (s, a_map) = server
        .post("/v1/maps", json!({"scenario_id": a_id, "kind": "gain"}))
        .await;
    assert_eq!(s, StatusCode::OK, "{a_map}");
    let b_doc = scenario("small-test.json", |v| v["name"] = "b".into());
    let (s, b) = server.post("/v1/scenarios", b_doc).await;
    assert_eq!(s, StatusCode::CREATED, "a and its map made room: {b}");
    let a_map_path = format!("/v1/maps/{}", a_map["map_id"].as_str().unwrap());
    let deadline = Instant::now() + Duration::from_secs(5);
    while server.get(&a_map_path).await.0 != StatusCode::NOT_FOUND {
        assert!(Instant::now() < deadline, "a's map went with a");
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    let (s, _) = server.get(&format!("/v1/scenarios/{a_id}")).await;
    assert_eq!(s, StatusCode::NOT_FOUND);

    for (method, path, status, code) in [
        (
            "GET",
            "/v1/scenarios/nope",
            StatusCode::NOT_FOUND,
            "not_found",
        ),
        ("GET", "/v1/maps/nope", StatusCode::NOT_FOUND, "not_found"),
        (
            "GET",
            "/v1/maps/nope/coverage?threshold=1",
            StatusCode::NOT_FOUND,
            "not_found",
        ),
        ("GET", "/v1/jobs/nope", StatusCode::NOT_FOUND, "not_found"),
        (
            "DELETE",
            "/v1/jobs/nope",
            StatusCode::NOT_FOUND,
            "not_found",
        ),
        (
            "GET",
            "/v2/anything",
            StatusCode::NOT_FOUND,
            "route_not_found",
        ),
        (
            "PUT",
            "/v1/paths",
            StatusCode::METHOD_NOT_ALLOWED,
            "method_not_allowed",
        ),
    ] {
        let (s, b) = server.send(method, path, None).await;
        problem(s, &b, status, code);
    }
    let (_, m) = server
        .post("/v1/maps", json!({"scenario_id": id, "kind": "gain"}))
        .await;
    let (s, b) = server
        .get(&format!(
            "/v1/maps/{}/coverage",
            m["map_id"].as_str().unwrap()
        ))
        .await;
    problem(s, &b, StatusCode::UNPROCESSABLE_ENTITY, "invalid_field");
    assert_eq!(b["field"], "threshold");
}

/// What users create can be deleted; an explicit null is never "absent"; exactly one of
/// scenario_id and scenario.
#[tokio::test]
async fn scenarios_and_maps_can_be_deleted_and_nulls_are_rejected() {
    let server = start(&[]);
    let doc = scenario("small-test.json", |v| v["name"] = "to-delete".into());
    let (_, created) = server.post("/v1/scenarios", doc).await;
    let id = created["id"].as_str().unwrap().to_string();
    let (_, map) = server
        .post("/v1/maps", json!({"scenario_id": id, "kind": "gain"}))
        .await;
    let map_path = format!("/v1/maps/{}", map["map_id"].as_str().unwrap());
    let (s, _) = server
        .send("DELETE", &format!("/v1/scenarios/{id}"), None)
        .await;
    assert_eq!(s, StatusCode::NO_CONTENT);
    let (s, b) = server.get(&map_path).await;
    problem(s, &b, StatusCode::NOT_FOUND, "not_found");
    let (s, b) = server
        .send("DELETE", &format!("/v1/scenarios/{id}"), None)
        .await;
    problem(s, &b, StatusCode::NOT_FOUND, "not_found");
    let builtin = server.scenario_id("small-test").await;
    let (s, b) = server
        .send("DELETE", &format!("/v1/scenarios/{builtin}"), None)
        .await;
    problem(s, &b, StatusCode::CONFLICT, "scenario_protected");
    let (s, b) = server.send("DELETE", "/v1/maps/nope", None).await;
    problem(s, &b, StatusCode::NOT_FOUND, "not_found");

    for (path, body, field) in [
        (
            "/v1/scenarios",
            scenario("small-test.json", |v| v["irs"] = Value::Null),
            "irs",
        ),
        (
            "/v1/maps",
            json!({"scenario": null, "scenario_id": builtin, "kind": "gain"}),
            "scenario",
        ),
        (
            "/v1/maps",
            json!({"scenario_id": builtin, "kind": "gain", "phases": null}),
            "phases",
        ),
        (
            "/v1/paths",
            json!({"map_id": null, "start": [0, 0], "goal": [1, 1], "threshold": 1}),
            "map_id",
        ),
    ] {
        let (s, b) = server.post(path, body).await;
        assert_eq!(s, StatusCode::UNPROCESSABLE_ENTITY, "{b}");
        assert_eq!(b["field"], field, "{b}");
    }
    let (s, b) = server
        .post(
            "/v1/paths",
            json!({"map": {"scenario_id": builtin, "kind": "gain"}, "start": [0, 0], "goal": [1, 1], "threshold": 1, "seed": 9007199254740992u64}),
        )
        .await;
    problem(s, &b, StatusCode::UNPROCESSABLE_ENTITY, "limit_exceeded");
    assert_eq!(b["field"], "seed");
}

/// A repeated path query is answered from the answer cache, byte for byte as the first time
/// but for `took_ms`; any other field makes another answer; a deleted map's kept answers are
/// never served; `--answer-cache-mb 0` keeps nothing.
#[tokio::test]
async fn repeated_path_queries_are_answered_from_the_answer_cache() {
    let server = start(&[]);
    let doc = scenario("small-test.json", |v| v["name"] = "answers".into());
    let (_, created) = server.post("/v1/scenarios", doc).await;
    let id = created["id"].as_str().unwrap().to_string();
    let (_, map) = server
        .post("/v1/maps", json!({"scenario_id": id, "kind": "gain"}))
        .await;
    let map_id = map["map_id"].as_str().unwrap().to_string();
    let query =
        json!({"map_id": map_id, "start": [0.5, 0.5], "goal": [5.5, 3.5], "threshold": "max"});
    let untimed = |mut answer: Value| {
        assert!(answer["took_ms"].as_f64().unwrap() >= 0.0, "{answer}");
        answer.as_object_mut().unwrap().remove("took_ms");
        answer
    };
    let hits = "irs_answer_cache_requests_total{outcome=\"hit\"}";
    let (s1, first) = server.post("/v1/paths", query.clone()).await;
    assert_eq!(server.metric(hits).await, 0.0);
    let (s2, second) = server.post("/v1/paths", query.clone()).await;
    assert_eq!((s1, s2), (StatusCode::OK, StatusCode::OK), "{first}");
    assert_eq!(server.metric(hits).await, 1.0);
    assert!(first["feasible"].as_bool().unwrap());
    assert_eq!(untimed(first.clone()), untimed(second));
    // A kept answer goes out as its text and then took_ms, with their length stated.
    let reply = server
        .client
        .post(format!("{}/v1/paths", server.base))
        .json(&query)
        .send()
        .await
        .unwrap();
    let stated = reply.content_length();
    let text = reply.bytes().await.unwrap();
    assert_eq!(stated, Some(text.len() as u64));
    let third: Value = serde_json::from_slice(&text).unwrap();
    assert_eq!(untimed(third), untimed(first.clone()));
    assert_eq!(server.metric(hits).await, 2.0);
    // Another precision, another answer (and not a hit).
    let mut full = query.clone();
    full["phase_precision"] = "full".into();
    let (_, other) = server.post("/v1/paths", full).await;
    assert_ne!(untimed(other), untimed(first));
    assert_eq!(server.metric(hits).await, 2.0);
    // The map goes: its kept answer is not served.
    let (s, _) = server
        .send("DELETE", &format!("/v1/maps/{map_id}"), None)
        .await;
    assert_eq!(s, StatusCode::NO_CONTENT);
    let (s, b) = server.post("/v1/paths", query).await;
    problem(s, &b, StatusCode::NOT_FOUND, "not_found");

    let keeping_none = start(&["--answer-cache-mb", "0"]);
    let small = keeping_none.scenario_id("small-test").await;
    let query = json!({"map": {"scenario_id": small, "kind": "gain"}, "start": [0.5, 0.5], "goal": [5.5, 3.5], "threshold": 1});
    for _ in 0..3 {
        let (s, b) = keeping_none.post("/v1/paths", query.clone()).await;
        assert_eq!(s, StatusCode::OK, "{b}");
    }
    assert_eq!(keeping_none.metric(hits).await, 0.0);
}

/// Big answers are compressed when the client accepts it; PNGs are not (already compressed).
#[tokio::test]
async fn answers_are_compressed_when_accepted() {
    let server = start(&[]);
    let url = server.paper_gain_map_url().await;
    let plain = server.client.get(&url).send().await.unwrap();
    assert!(plain.headers().get("content-encoding").is_none());
    let plain_len = plain.bytes().await.unwrap().len();
    for (encoding, magic) in [("gzip", &[0x1f, 0x8b][..]), ("br", &[][..])] {
        let resp = server
            .client
            .get(&url)
            .header("accept-encoding", encoding)
            .send()
            .await
            .unwrap();
        assert_eq!(resp.headers()["content-encoding"], encoding);
        let bytes = resp.bytes().await.unwrap();
        assert!(bytes.starts_with(magic));
        assert!(
            bytes.len() * 3 < plain_len,
            "{encoding}: {} of {plain_len} bytes",
            bytes.len()
        );
    }
    let png = server
        .client
        .get(format!("{url}/image.png"))
        .header("accept-encoding", "gzip")
        .send()
        .await
        .unwrap();
    assert!(png.headers().get("content-encoding").is_none());
}

#[tokio::test]
async fn operations_endpoints() {
    let server = start(&[]);
    assert_eq!(
        server.get("/healthz").await,
        (StatusCode::OK, json!({"status": "ok"}))
    );
    let (s, ready) = server.get("/readyz").await;
    assert_eq!(
        ready,
        json!({"status": "ready", "scenarios": 3, "degraded": []})
    );
    assert_eq!(s, StatusCode::OK);
    let (_, version) = server.get("/version").await;
    assert_eq!(version["version"], env!("CARGO_PKG_VERSION"));
    server.get("/v1/scenarios").await;
    assert!(
        server
            .metric("http_requests_total{route=\"/v1/scenarios\",method=\"GET\",status=\"200\"}")
            .await
            >= 1.0
    );
    assert!(
        server
            .metric("http_request_duration_seconds_count{route=\"/v1/scenarios\"}")
            .await
            >= 1.0
    );
    // Every series rendered says what it is (HELP and TYPE).
    let text = server.metrics_text().await;
    for name in text
        .lines()
        .filter(|l| !l.starts_with('#') && !l.is_empty())
        .map(|l| l.split(['{', ' ']).next().unwrap())
        .map(|n| {
            n.trim_end_matches("_bucket")
                .trim_end_matches("_sum")
                .trim_end_matches("_count")
        })
    {
        assert!(
            text.contains(&format!("# HELP {name} ")) && text.contains(&format!("# TYPE {name} ")),
            "{name} has no HELP or TYPE line:\n{text}"
        );
    }
    assert_eq!(server.metric("irs_scenarios").await, 3.0);
    // Read at the scrape: the process's own series and the jobs' depth.
    assert!(server.metric("process_resident_memory_bytes").await > 1e6);
    assert!(server.metric("process_start_time_seconds").await > 1.7e9);
    assert!(server.metric("process_open_fds").await >= 3.0);
    assert_eq!(server.metric("irs_jobs_waiting").await, 0.0);
    assert_eq!(server.metric("irs_jobs_running").await, 0.0);
}

#[tokio::test]
async fn sigterm_shuts_down_gracefully() {
    let mut server = start_binary(&["--shutdown-grace-s", "1"]);
    assert_eq!(server.get("/healthz").await.0, StatusCode::OK);
    // A build that outlasts the grace period is cancelled, and the process exits within the
    // grace period plus two seconds.
    let (s, job) = server
        .post(
            "/v1/maps",
            long_rate_request(fine_multi_user("shutdown"), "noma"),
        )
        .await;
    assert_eq!(s, StatusCode::ACCEPTED, "{job}");
    let signalled = Instant::now();
    server.sigterm();
    let deadline = Instant::now() + Duration::from_secs(10);
    loop {
        if let Some(status) = server.child().try_wait().unwrap() {
            assert!(status.success(), "exit status {status}");
            assert!(
                signalled.elapsed() < Duration::from_secs(4),
                "exit took {:?}",
                signalled.elapsed()
            );
            break;
        }
        assert!(
            Instant::now() < deadline,
            "the server did not stop on SIGTERM"
        );
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
}

#[tokio::test]
async fn map_image_is_a_png_with_the_path() {
    let server = start(&[]);
    let map_url = server.paper_gain_map_url().await;
    let url = format!("{map_url}/image.png?start=-10,0&goal=10,0&threshold=-61");
    let resp = server.client.get(url).send().await.unwrap();
    assert_eq!(resp.status(), StatusCode::OK);
    assert_eq!(resp.headers()["content-type"], "image/png");
    let bytes = resp.bytes().await.unwrap();
    assert_eq!(&bytes[..8], b"\x89PNG\r\n\x1a\n");
    let url = format!("{map_url}/image.png?start=-10,0");
    let (status, body) = server.get(url.strip_prefix(&server.base).unwrap()).await;
    problem(
        status,
        &body,
        StatusCode::UNPROCESSABLE_ENTITY,
        "invalid_field",
    );
    assert_eq!(body["field"], "goal");
}

/// The warehouse's floor plan through the API: registered inline as `irs-planner scenario`
/// prints it (the same scenario and map ids as the CLI's), a gain map, its Nav2 masks as tar
/// archives and its values as .npy. A file reference or a bad image is 422 naming the field,
/// and nothing is registered.
#[tokio::test]
async fn floor_plans_and_exports_over_http() {
    let server = start(&[]);
    let cli = |args: &[&str]| -> Value {
        let out = Command::new(env!("CARGO_BIN_EXE_irs-planner"))
            .args(args)
            .current_dir(root())
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        serde_json::from_slice(&out.stdout).unwrap()
    };
    let file = "scenarios/warehouse/warehouse.json";
    let doc = cli(&["scenario", "--scenario", file]);
    let cli_map = cli(&["map", "--scenario", file, "--kind", "gain", "--quiet"]);
    let (status, registered) = server.post("/v1/scenarios", doc.clone()).await;
    assert_eq!(status, StatusCode::CREATED, "{registered}");
    assert_eq!(registered["id"], cli_map["key"]["scenario_id"]);
    let (status, map) = server
        .post(
            "/v1/maps",
            json!({"scenario_id": registered["id"], "kind": "gain"}),
        )
        .await;
    assert_eq!(status, StatusCode::OK, "{map}");
    assert_eq!(map["map_id"], cli_map["map_id"]);
    let map_url = format!(
        "{}/v1/maps/{}",
        server.base,
        map["map_id"].as_str().unwrap()
    );

    let fetch = |url: String| {
        let client = server.client.clone();
        async move {
            let resp = client.get(url).send().await.unwrap();
            let status = resp.status();
            let kind = resp.headers()["content-type"].to_str().unwrap().to_string();
            (status, kind, resp.bytes().await.unwrap().to_vec())
        }
    };
    for (query, stem) in [
        ("threshold=-70", "keepout"),
        ("threshold=-70&mask=cost&best=-50", "cost"),
    ] {
        let (status, kind, bytes) = fetch(format!("{map_url}/nav2-mask?{query}")).await;
        assert_eq!(
            (status, kind.as_str()),
            (StatusCode::OK, "application/x-tar")
        );
        let mut archive = tar::Archive::new(bytes.as_slice());
        let mut entries: Vec<(String, Vec<u8>)> = Vec::new();
        for entry in archive.entries().unwrap() {
            let mut entry = entry.unwrap();
            let mut data = Vec::new();
            std::io::Read::read_to_end(&mut entry, &mut data).unwrap();
            entries.push((entry.path().unwrap().display().to_string(), data));
        }
        assert_eq!(entries[0].0, format!("{stem}.yaml"));
        assert_eq!(entries[1].0, format!("{stem}.pgm"));
        let yaml = String::from_utf8(entries[0].1.clone()).unwrap();
        assert!(
            yaml.contains("resolution: 0.25") && yaml.contains("-30.125"),
            "{yaml}"
        );
        assert!(entries[1].1.starts_with(b"P5\n241 161"));
    }
    let (status, kind, bytes) = fetch(format!("{map_url}/values.npy")).await;
    assert_eq!(
        (status, kind.as_str()),
        (StatusCode::OK, "application/octet-stream")
    );
    let npy = npyz::NpyFile::new(bytes.as_slice()).unwrap();
    assert_eq!(npy.shape(), [241, 161]);

    for (query, field) in [
        ("", "threshold"),
        ("threshold=-70&mask=speed", "mask"),
        ("threshold=-70&best=-50", "best"),
        ("threshold=-70&mask=cost&best=-80", "best"),
        ("threshold=x", "threshold"),
        ("threshold=-70&colour=1", "colour"),
    ] {
        let (status, body) = server
            .get(&format!(
                "/v1/maps/{}/nav2-mask?{query}",
                map["map_id"].as_str().unwrap()
            ))
            .await;
        problem(
            status,
            &body,
            StatusCode::UNPROCESSABLE_ENTITY,
            "invalid_field",
        );
        assert_eq!(body["field"], field, "{query}: {body}");
    }

    let (_, before) = server.get("/v1/scenarios").await;
    let count = before["scenarios"].as_array().unwrap().len();
    let mut by_reference = doc.clone();
    by_reference["floor_plan"] = json!({"map": "map.yaml"});
    let (status, body) = server.post("/v1/scenarios", by_reference).await;
    problem(
        status,
        &body,
        StatusCode::UNPROCESSABLE_ENTITY,
        "invalid_scenario",
    );
    assert_eq!(body["field"], "floor_plan.map");
    let mut colour = doc.clone();
    colour["floor_plan"]["image"] = "UDYKMSAxCjI1NQoAAAA=".into(); // "P6\n1 1\n255\n\0\0\0"
    let (status, body) = server.post("/v1/scenarios", colour).await;
    problem(
        status,
        &body,
        StatusCode::UNPROCESSABLE_ENTITY,
        "invalid_scenario",
    );
    assert_eq!(body["field"], "floor_plan.image");
    let mut yawed = doc;
    yawed["floor_plan"]["origin"] = json!([-30.0, -20.0, 0.1]);
    let (status, body) = server.post("/v1/scenarios", yawed).await;
    problem(
        status,
        &body,
        StatusCode::UNPROCESSABLE_ENTITY,
        "invalid_scenario",
    );
    assert_eq!(body["field"], "floor_plan.origin");
    let (_, after) = server.get("/v1/scenarios").await;
    assert_eq!(after["scenarios"].as_array().unwrap().len(), count);
}

/// Placement over HTTP: a small search answers while the request waits, its best candidates are
/// registered with their maps cached (a path query on the best map id works at once), the
/// ranking is readable again by id; a large search is a job with progress; every bad search is
/// a 422 naming its field.
#[tokio::test]
async fn placements_rank_candidates_and_keep_the_best_ready() {
    let server = start(&["--sync-cells", "20000"]);
    let id = server.scenario_id("paper-single-user").await;
    let south = json!({"walls": [{"from": [-10, -10], "to": [10, -10]}], "step_m": 1.0});
    let request = json!({
        "scenario_id": id, "candidates": south,
        "objective": {"kind": "max_threshold", "start": [-10, 0], "goal": [10, 0]},
    });
    let (status, body) = server.post("/v1/placements", request.clone()).await;
    assert_eq!(status, StatusCode::OK, "{body}");
    assert_eq!(body["map_kind"], "gain");
    assert_eq!(body["registered"], 3);
    let ranked = body["candidates"].as_array().unwrap();
    assert_eq!(ranked.len(), 21, "{}", body["rejected"]);
    assert_eq!(
        ranked[0]["center"],
        json!([0.0, -10.0, 2.0]),
        "the paper's pose is the best"
    );
    let best_map = ranked[2]["map_id"].as_str().unwrap();
    let (status, path) = server
        .post(
            "/v1/paths",
            json!({"map_id": best_map, "start": [-10, 0], "goal": [10, 0], "threshold": "max"}),
        )
        .await;
    assert_eq!(status, StatusCode::OK, "{path}");
    assert!(
        (path["max_feasible_threshold"].as_f64().unwrap() - ranked[2]["score"].as_f64().unwrap())
            .abs()
            < 1e-9
    );
    let (status, _) = server
        .get(&format!(
            "/v1/maps/{}",
            ranked[3]["map_id"].as_str().unwrap()
        ))
        .await;
    assert_eq!(
        status,
        StatusCode::NOT_FOUND,
        "only the best three are built"
    );
    let (status, again) = server.get(body["href"].as_str().unwrap()).await;
    assert_eq!(status, StatusCode::OK);
    assert_eq!(again["candidates"], body["candidates"]);

    // 4 walls × 41 samples on 1681 cells is above 4 × 20 000 cell evaluations: a job.
    let corners = [[-10, -10], [10, -10], [10, 10], [-10, 10]];
    let walls: Vec<Value> = (0..4)
        .map(|k| json!({"from": corners[k], "to": corners[(k + 1) % 4]}))
        .collect();
    let (status, job) = server
        .post(
            "/v1/placements",
            json!({
                "scenario_id": id, "candidates": {"walls": walls, "step_m": 0.5},
                "objective": {"kind": "coverage", "threshold": -62}, "keep": 1,
            }),
        )
        .await;
    assert_eq!(status, StatusCode::ACCEPTED, "{job}");
    assert_eq!(job["kind"], "placement");
    let done = server.wait_job(job["job_id"].as_str().unwrap()).await;
    assert_eq!(done["state"], "done");
    assert_eq!(done["cells_done"], done["cells_total"]);
    let (status, ranking) = server.get(done["result_href"].as_str().unwrap()).await;
    assert_eq!(status, StatusCode::OK, "{ranking}");
    assert_eq!(ranking["registered"], 1);
    assert_eq!(
        ranking["rejected"].as_array().unwrap().len(),
        41,
        "the AP's wall"
    );
    assert_eq!(ranking["unit"], "fraction");

    let bad = |edit: fn(&mut Value)| {
        let mut r = request.clone();
        edit(&mut r);
        r
    };
    type Edit = fn(&mut Value);
    let cases: [(Edit, &str); 6] = [
        (|r| r["index"] = 1.into(), "index"),
        (
            |r| r["candidates"] = json!({"positions": [[0, 0, 2]]}),
            "candidates.positions",
        ),
        (
            |r| r["objective"]["start"] = json!([-11, 0]),
            "objective.start",
        ),
        (|r| r["keep"] = 21.into(), "keep"),
        (
            |r| r["candidates"]["step_m"] = 0.0001.into(),
            "candidates.step_m",
        ),
        (|r| r["phases"] = "none".into(), "phases"),
    ];
    for (edit, field) in cases {
        let (status, problem_body) = server.post("/v1/placements", bad(edit)).await;
        assert_eq!(
            status,
            StatusCode::UNPROCESSABLE_ENTITY,
            "{field}: {problem_body}"
        );
        assert_eq!(problem_body["field"], field, "{problem_body}");
    }
    let (status, _) = server.get("/v1/placements/nope").await;
    assert_eq!(status, StatusCode::NOT_FOUND);
}

/// A long placement search is a job like a map build: it reports progress and a cancel stops it.
#[tokio::test]
async fn a_placement_job_can_be_cancelled() {
    let server = start(&["--sync-cells", "1000"]);
    // The paper floor at 0.05 m (401² cells) and every 0.25 m of three walls: 78 M evaluations,
    // seconds of work (at 0.1 m and 0.5 m it could finish before the cancel arrived).
    let doc = scenario("paper-single-user.json", |v| {
        v["grid"]["resolution_m"] = 0.05.into();
        v["name"] = "paper-fine".into();
    });
    let corners = [[-10, 10], [-10, -10], [10, -10], [10, 10]];
    let walls: Vec<Value> = (0..3)
        .map(|k| json!({"from": corners[k], "to": corners[k + 1]}))
        .collect();
    let (status, job) = server
        .post(
            "/v1/placements",
            json!({
                "scenario": doc, "candidates": {"walls": walls, "step_m": 0.25},
                "objective": {"kind": "coverage", "threshold": -62},
            }),
        )
        .await;
    assert_eq!(status, StatusCode::ACCEPTED, "{job}");
    let id = job["job_id"].as_str().unwrap();
    let (status, body) = server.get(&format!("/v1/placements/{id}")).await;
    problem(status, &body, StatusCode::CONFLICT, "placement_not_ready");
    // Cancelled once it is scoring (it has a total), so the cancel is seen to stop the work
    // itself, not only the listing of the candidates before it.
    let deadline = Instant::now() + Duration::from_secs(60);
    loop {
        let (_, job) = server.get(&format!("/v1/jobs/{id}")).await;
        if job["cells_total"].as_u64().unwrap_or(0) > 0 {
            break;
        }
        assert!(Instant::now() < deadline, "the search never started: {job}");
        tokio::time::sleep(Duration::from_millis(5)).await;
    }
    let (status, _) = server.send("DELETE", &format!("/v1/jobs/{id}"), None).await;
    assert_eq!(status, StatusCode::ACCEPTED);
    let done = server.wait_job(id).await;
    assert_eq!(done["state"], "cancelled", "{done}");
    assert!(done["cells_done"].as_u64().unwrap() < done["cells_total"].as_u64().unwrap());
    let (status, body) = server.get(&format!("/v1/placements/{id}")).await;
    problem(status, &body, StatusCode::CONFLICT, "job_finished");
}

/// Tokens on: writes need one, and jobs and scenarios belong to the token that made them.
#[tokio::test]
async fn tokens_guard_writes_and_records_belong_to_their_token() {
    let (alice, bob) = ("alice-token-0123456789", "bob-token-0123456789ab");
    let server = start(&["--api-tokens", &format!("{alice},{bob}")]);
    let doc = scenario("small-test.json", |v| v["name"] = "alice's".into());
    let (s, b) = server.post("/v1/scenarios", doc.clone()).await;
    problem(s, &b, StatusCode::UNAUTHORIZED, "unauthorized");
    let (s, b) = server
        .send_as(Some("not-a-token-at-all"), "GET", "/v1/scenarios", None)
        .await;
    problem(s, &b, StatusCode::UNAUTHORIZED, "unauthorized");
    let resp = server
        .client
        .delete(format!("{}/v1/jobs/x", server.base))
        .send()
        .await
        .unwrap();
    assert_eq!(resp.status(), StatusCode::UNAUTHORIZED);
    assert!(resp.headers().contains_key("www-authenticate"));

    let (s, created) = server
        .send_as(Some(alice), "POST", "/v1/scenarios", Some(doc))
        .await;
    assert_eq!(s, StatusCode::CREATED, "{created}");
    let id = created["id"].as_str().unwrap().to_string();
    let names = |list: &Value| -> Vec<String> {
        list["scenarios"]
            .as_array()
            .unwrap()
            .iter()
            .map(|s| s["name"].as_str().unwrap_or("").to_string())
            .collect()
    };
    let (_, mine) = server
        .send_as(Some(alice), "GET", "/v1/scenarios", None)
        .await;
    assert!(names(&mine).contains(&"alice's".to_string()), "{mine}");
    let (_, theirs) = server
        .send_as(Some(bob), "GET", "/v1/scenarios", None)
        .await;
    assert!(!names(&theirs).contains(&"alice's".to_string()), "{theirs}");
    let (_, anonymous) = server.get("/v1/scenarios").await;
    assert_eq!(
        names(&anonymous).len(),
        3,
        "only the built-in scenarios: {anonymous}"
    );
    // By id, an API scenario is its registrants' only: anybody else is told it does not exist.
    let path = format!("/v1/scenarios/{id}");
    assert_eq!(server.get(&path).await.0, StatusCode::NOT_FOUND);
    assert_eq!(
        server.send_as(Some(bob), "GET", &path, None).await.0,
        StatusCode::NOT_FOUND
    );
    assert_eq!(
        server.send_as(Some(alice), "GET", &path, None).await.0,
        StatusCode::OK
    );
    let (s, b) = server.send_as(Some(bob), "DELETE", &path, None).await;
    problem(s, &b, StatusCode::NOT_FOUND, "not_found");

    let (s, job) = server
        .send_as(
            Some(alice),
            "POST",
            "/v1/maps",
            Some(long_rate_request(fine_multi_user("alice-job"), "noma")),
        )
        .await;
    assert_eq!(s, StatusCode::ACCEPTED, "{job}");
    let job_path = format!("/v1/jobs/{}", job["job_id"].as_str().unwrap());
    let (s, b) = server.send_as(Some(bob), "DELETE", &job_path, None).await;
    problem(s, &b, StatusCode::NOT_FOUND, "not_found");
    let (_, bobs) = server.send_as(Some(bob), "GET", "/v1/jobs", None).await;
    assert_eq!(bobs["jobs"].as_array().unwrap().len(), 0, "{bobs}");
    let (_, alices) = server.send_as(Some(alice), "GET", "/v1/jobs", None).await;
    assert_eq!(alices["jobs"].as_array().unwrap().len(), 1, "{alices}");
    // Only its owners may follow it: the id alone is not enough.
    assert_eq!(server.get(&job_path).await.0, StatusCode::NOT_FOUND);
    assert_eq!(
        server.send_as(Some(bob), "GET", &job_path, None).await.0,
        StatusCode::NOT_FOUND
    );
    let (s, _) = server.send_as(Some(alice), "DELETE", &job_path, None).await;
    assert_eq!(s, StatusCode::ACCEPTED);
    server
        .wait_job_as(Some(alice), job["job_id"].as_str().unwrap())
        .await;
    let (s, _) = server.send_as(Some(alice), "DELETE", &path, None).await;
    assert_eq!(s, StatusCode::NO_CONTENT);
    assert_eq!(
        server.send_as(Some(alice), "GET", &path, None).await.0,
        StatusCode::NOT_FOUND
    );
}

/// Listings come a page at a time; following next_cursor visits every item once.
#[tokio::test]
async fn listings_are_paginated() {
    let server = start(&[]);
    for k in 0..5 {
        let doc = scenario("small-test.json", |v| {
            v["name"] = format!("page-{k}").into()
        });
        assert_eq!(
            server.post("/v1/scenarios", doc).await.0,
            StatusCode::CREATED
        );
    }
    let mut seen = Vec::new();
    let mut cursor: Option<String> = None;
    loop {
        let query = match &cursor {
            Some(c) => format!("/v1/scenarios?limit=2&cursor={c}"),
            None => "/v1/scenarios?limit=2".to_string(),
        };
        let (s, page) = server.get(&query).await;
        assert_eq!(s, StatusCode::OK, "{page}");
        let items = page["scenarios"].as_array().unwrap();
        assert!(items.len() <= 2);
        seen.extend(items.iter().map(|s| s["id"].as_str().unwrap().to_string()));
        match page["next_cursor"].as_str() {
            Some(next) => cursor = Some(next.to_string()),
            None => break,
        }
    }
    let mut unique = seen.clone();
    unique.sort();
    unique.dedup();
    assert_eq!(seen.len(), 8, "3 built-in + 5 registered: {seen:?}");
    assert_eq!(unique.len(), seen.len());
    for (query, field) in [
        ("/v1/scenarios?limit=0", "limit"),
        ("/v1/jobs?limit=1001", "limit"),
        ("/v1/maps?cursor=%2F..", "cursor"),
        ("/v1/jobs?page=2", "page"),
    ] {
        let (s, b) = server.get(query).await;
        assert_eq!(s, StatusCode::UNPROCESSABLE_ENTITY, "{query}: {b}");
        assert_eq!(b["field"], field, "{b}");
    }
}

/// Work above the CPU budget is refused before it starts, naming the field and the limit;
/// a client's request id is kept only if it is short and clean.
#[tokio::test]
async fn budgets_and_request_ids() {
    let server = start(&["--max-build-cpu-s", "0.001"]);
    let heavy = scenario("paper-single-user.json", |v| {
        v["irs"]["grouping"] = "elements".into();
        v["name"] = "heavy".into();
    });
    let (s, b) = server
        .post("/v1/maps", json!({"scenario": heavy, "kind": "gain"}))
        .await;
    problem(s, &b, StatusCode::UNPROCESSABLE_ENTITY, "limit_exceeded");
    assert_eq!(b["field"], "kind");
    assert_eq!(b["limit"], 1);
    let (_, listed) = server.get("/v1/scenarios").await;
    assert_eq!(
        listed["scenarios"].as_array().unwrap().len(),
        3,
        "the refused scenario left no trace"
    );

    let echo = |id: String| {
        let (client, url) = (server.client.clone(), format!("{}/healthz", server.base));
        async move {
            let resp = client
                .get(url)
                .header("x-request-id", id)
                .send()
                .await
                .unwrap();
            resp.headers()["x-request-id"].to_str().unwrap().to_string()
        }
    };
    assert_eq!(echo("trace-42.a:b".into()).await, "trace-42.a:b");
    let long = "x".repeat(65);
    assert_ne!(echo(long.clone()).await, long);
    assert_ne!(echo("a b;c=\"d\"".into()).await, "a b;c=\"d\"");
}

/// A map is handed to the requests that waited for it even when the cache cannot keep it (no
/// 500 when it is evicted at once), and a map bigger than the whole cache budget is refused
/// before its build.
#[tokio::test]
async fn maps_are_delivered_and_never_built_beyond_the_cache() {
    let server = start(&["--cache-mb", "2"]);
    let fine = |resolution: f64, name: &str| {
        scenario("paper-single-user.json", |v| {
            v["grid"]["resolution_m"] = resolution.into();
            v["name"] = name.into();
        })
    };
    // 1.5 MB each: every build evicts the map before it.
    let requests: Vec<Value> = (0..4)
        .map(|k| json!({"scenario": fine(0.05, &format!("fine-{k}")), "kind": "gain"}))
        .collect();
    let answers = futures_join_all(&server, &requests).await;
    for (status, body) in &answers {
        assert_eq!(*status, StatusCode::OK, "{body}");
    }
    assert!(server.metric("irs_map_cache_bytes").await <= 2.0 * 1024.0 * 1024.0);
    let (s, b) = server
        .post(
            "/v1/maps",
            json!({"scenario": fine(0.025, "too-fine"), "kind": "gain"}),
        )
        .await;
    problem(s, &b, StatusCode::UNPROCESSABLE_ENTITY, "limit_exceeded");
    assert_eq!(b["limit"], 2 * 1024 * 1024);
}

/// Writes `request` on a new loopback connection whose receive buffer is as small as the
/// kernel allows, and never reads: the client that stops reading.
async fn unread_request(base: &str, request: &str) -> tokio::net::TcpStream {
    use tokio::io::AsyncWriteExt;
    let addr: std::net::SocketAddr = base.strip_prefix("http://").unwrap().parse().unwrap();
    let socket = tokio::net::TcpSocket::new_v4().unwrap();
    socket.set_recv_buffer_size(4096).unwrap();
    let mut stream = socket.connect(addr).await.unwrap();
    stream.write_all(request.as_bytes()).await.unwrap();
    stream
}

/// Reads until the server closes (or resets) the connection; the bytes read and how long that
/// took.
async fn read_to_close(stream: &mut tokio::net::TcpStream, limit: Duration) -> (usize, Duration) {
    use tokio::io::AsyncReadExt;
    let started = Instant::now();
    let mut total = 0;
    let mut buf = vec![0u8; 1 << 16];
    loop {
        match tokio::time::timeout_at((started + limit).into(), stream.read(&mut buf)).await {
            Ok(Ok(0)) | Ok(Err(_)) => return (total, started.elapsed()),
            Ok(Ok(n)) => total += n,
            Err(_) => panic!("the connection was still open after {limit:?} ({total} bytes read)"),
        }
    }
}

/// A client that stops reading a 15.8 MB map body holds it against `--answers-in-flight-mb`
/// (another client asking meanwhile gets 503 `answers_in_flight`) until `--write-timeout-s`
/// closes its connection, which frees the budget: the next request is answered in full.
#[tokio::test]
async fn a_client_that_stops_reading_is_cut_off_and_its_answer_freed() {
    // A write timeout of 10 s: the second request's answer is built (then refused) while the
    // first stalls, which on a loaded CI machine took more than 3 s (a test build serialises
    // a million cells slowly).
    let server = start(&[
        "--write-timeout-s",
        "10",
        "--answers-in-flight-mb",
        "20",
        "--sync-cells",
        "2000000",
    ]);
    let fine = scenario("paper-single-user.json", |v| {
        v["grid"]["resolution_m"] = 0.02.into();
        v["name"] = "two-cm".into();
    });
    let (status, map) = server
        .post("/v1/maps", json!({"scenario": fine, "kind": "gain"}))
        .await;
    assert_eq!(status, StatusCode::OK, "{map}");
    let path = format!("/v1/maps/{}", map["map_id"].as_str().unwrap());
    let full = server
        .client
        .get(format!("{}{path}", server.base))
        .send()
        .await
        .unwrap()
        .bytes()
        .await
        .unwrap()
        .len();
    assert!(full > 15_000_000, "{full} bytes");
    let mut stalled = unread_request(
        &server.base,
        &format!("GET {path} HTTP/1.1\r\nhost: test\r\n\r\n"),
    )
    .await;
    // The stalled answer holds 15.8 of the 20 MiB (once built: slow in a test build): a second
    // one does not fit.
    let in_flight = || server.metric("irs_answers_in_flight_bytes");
    let deadline = Instant::now() + Duration::from_secs(60);
    while in_flight().await < 15e6 {
        assert!(
            Instant::now() < deadline,
            "the unread answer never held the budget"
        );
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    let (status, body) = server.get(&path).await;
    problem(
        status,
        &body,
        StatusCode::SERVICE_UNAVAILABLE,
        "answers_in_flight",
    );
    assert_eq!(body["limit"], 20 * 1024 * 1024);
    // Cut off within the write timeout plus the watchdog's tick, which frees the budget;
    // reading then gets what the socket buffers held, then the end.
    let deadline = Instant::now() + Duration::from_secs(30);
    while in_flight().await > 0.0 {
        assert!(Instant::now() < deadline, "the budget was not freed");
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
    let (received, _) = read_to_close(&mut stalled, Duration::from_secs(5)).await;
    assert!(received < full, "{received} of {full} bytes");
    let resp = server
        .client
        .get(format!("{}{path}", server.base))
        .send()
        .await
        .unwrap();
    assert_eq!(resp.status(), StatusCode::OK);
    // The whole body again (its `took_ms` may take a digit more or less).
    let again = resp.bytes().await.unwrap().len();
    assert!(again.abs_diff(full) < 16, "{again} bytes, {full} before");
    assert_eq!(
        server.metric("irs_connections_stalled_closed_total").await,
        1.0
    );
    assert!(server.metric("irs_answers_refused_in_flight_total").await >= 1.0);
}

/// An HTTP/2 connection that only sends PINGs is closed by the idle timeout (PINGs are not
/// requests), and one client address holds at most `--max-connections-per-client`.
#[tokio::test]
async fn pings_do_not_keep_a_connection_and_one_client_holds_a_bounded_share() {
    use tokio::io::AsyncWriteExt;
    let server = start(&["--idle-timeout-s", "1", "--max-connections-per-client", "2"]);
    // h2c with prior knowledge: the preface, an empty SETTINGS frame, then a PING every 200 ms.
    let mut pinging = unread_request(&server.base, "PRI * HTTP/2.0\r\n\r\nSM\r\n\r\n").await;
    pinging
        .write_all(&[0, 0, 0, 0x4, 0, 0, 0, 0, 0])
        .await
        .unwrap();
    let started = Instant::now();
    let (mut reader, mut writer) = pinging.into_split();
    let pinger = tokio::spawn(async move {
        let ping = [0, 0, 8, 0x6, 0, 0, 0, 0, 0, 1, 2, 3, 4, 5, 6, 7, 8];
        while writer.write_all(&ping).await.is_ok() {
            tokio::time::sleep(Duration::from_millis(200)).await;
        }
    });
    let closed = {
        use tokio::io::AsyncReadExt;
        let mut buf = vec![0u8; 4096];
        loop {
            match tokio::time::timeout(Duration::from_secs(6), reader.read(&mut buf)).await {
                Ok(Ok(0)) | Ok(Err(_)) => break started.elapsed(),
                Ok(Ok(_)) => {}
                Err(_) => panic!("a PING-only connection was still open after 6 s"),
            }
        }
    };
    pinger.abort();
    assert!(closed < Duration::from_secs(4), "closed after {closed:?}");
    assert_eq!(
        server.metric("irs_connections_idle_closed_total").await,
        1.0
    );
    // Once the metrics request's kept-alive connection has idled out, two connections held
    // open: a third from the same address is closed at once, and served again once one goes.
    tokio::time::sleep(Duration::from_millis(1600)).await;
    let idle_client = |_| unread_request(&server.base, "");
    let first = idle_client(0).await;
    let second = idle_client(1).await;
    let mut third = idle_client(2).await;
    let (_, after) = read_to_close(&mut third, Duration::from_secs(2)).await;
    assert!(after < Duration::from_secs(1));
    drop(first);
    drop(second);
    tokio::time::sleep(Duration::from_millis(200)).await;
    let fresh = Server {
        running: Running::InProcess(tokio::spawn(async { Ok(()) })),
        base: server.base.clone(),
        client: client(),
    };
    assert!(
        fresh
            .metric("irs_connections_refused_per_client_total")
            .await
            >= 1.0
    );
}

/// CORS is deliberate: no CORS headers unless origins are configured, and then only for them.
#[tokio::test]
async fn cors_only_for_configured_origins() {
    let preflight = |server: &Server, origin: &'static str| {
        let (client, url) = (server.client.clone(), format!("{}/v1/paths", server.base));
        async move {
            let resp = client
                .request(reqwest::Method::OPTIONS, url)
                .header("origin", origin)
                .header("access-control-request-method", "POST")
                .header("access-control-request-headers", "content-type")
                .send()
                .await
                .unwrap();
            resp.headers()
                .get("access-control-allow-origin")
                .map(|v| v.to_str().unwrap().to_string())
        }
    };
    let closed = start(&[]);
    assert_eq!(preflight(&closed, "https://fleet.example").await, None);
    let open = start(&["--cors-origin", "https://fleet.example"]);
    assert_eq!(
        preflight(&open, "https://fleet.example").await.as_deref(),
        Some("https://fleet.example")
    );
    assert_eq!(preflight(&open, "https://elsewhere.example").await, None);
}

/// `--data-dir`: a map build that a SIGTERM's grace period cuts short is recorded with the
/// grid rows it had solved, and the next start resumes it under the same id, for the same
/// owner, copying those rows, until its map is built: the same map as a build never stopped.
#[tokio::test]
async fn a_build_interrupted_by_sigterm_resumes_after_the_restart() {
    let dir = std::env::temp_dir().join(format!("irs-resume-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let (alice, bob) = ("alice-token-0123456789", "bob-token-0123456789ab");
    let tokens = format!("{alice},{bob}");
    let dir_flag = dir.to_str().unwrap();
    let flags = [
        "--data-dir",
        dir_flag,
        "--api-tokens",
        &tokens,
        "--shutdown-grace-s",
        "0",
    ];
    let mut server = start_binary(&flags);
    // The rate-map build of an 81² floor named `name`.
    let rate_request = |name: &str| {
        let floor = scenario("paper-multi-user.json", |v| {
            v["grid"]["resolution_m"] = 0.25.into();
            v["name"] = name.into();
        });
        long_rate_request(floor, "noma")
    };
    // Alice's job building it.
    let rate_job = async |name: &str| {
        let (s, job) = server
            .send_as(Some(alice), "POST", "/v1/maps", Some(rate_request(name)))
            .await;
        assert_eq!(s, StatusCode::ACCEPTED, "{job}");
        job
    };
    let job_id = rate_job("resumed").await["job_id"]
        .as_str()
        .unwrap()
        .to_string();
    let job_path = format!("/v1/jobs/{job_id}");
    // At least ten rows solved before the stop, which the next start copies: ten rows' worth
    // of cells more than the build's threads may each have in a row half done.
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get()) as u64;
    let deadline = Instant::now() + Duration::from_secs(60);
    loop {
        let (_, job) = server.send_as(Some(alice), "GET", &job_path, None).await;
        if job["cells_done"].as_u64().unwrap() >= (10 + threads) * 81 {
            break;
        }
        assert!(Instant::now() < deadline, "no progress: {job}");
        tokio::time::sleep(Duration::from_millis(10)).await;
    }
    // A second build, whose scenario is gone by the next start: settled as failed.
    let orphaned = rate_job("orphaned").await;
    let orphaned_path = format!("/v1/jobs/{}", orphaned["job_id"].as_str().unwrap());
    let (_, orphaned_job) = server
        .send_as(Some(alice), "GET", &orphaned_path, None)
        .await;
    let orphaned_sid = orphaned_job["scenario_id"].as_str().unwrap().to_string();
    server.sigterm();
    let status = server.child().wait().unwrap();
    assert!(status.success(), "exit status {status}");
    drop(server);
    for entry in std::fs::read_dir(dir.join("scenarios")).unwrap() {
        let path = entry.unwrap().path();
        if path
            .file_name()
            .unwrap()
            .to_string_lossy()
            .starts_with(&orphaned_sid)
        {
            std::fs::remove_file(path).unwrap();
        }
    }

    let server = start_binary(&flags);
    let (s, failed) = server
        .send_as(Some(alice), "GET", &orphaned_path, None)
        .await;
    assert_eq!(
        s,
        StatusCode::OK,
        "settled at start-up, visible at once: {failed}"
    );
    assert_eq!(failed["state"], "failed", "{failed}");
    assert!(
        failed["error"]
            .as_str()
            .unwrap()
            .contains("no longer registered"),
        "{failed}"
    );
    let (s, resumed) = server.send_as(Some(alice), "GET", &job_path, None).await;
    assert_eq!(s, StatusCode::OK, "{resumed}");
    assert_ne!(resumed["state"], "cancelled", "{resumed}");
    let (s, _) = server.send_as(Some(bob), "GET", &job_path, None).await;
    assert_eq!(s, StatusCode::NOT_FOUND, "still alice's alone");
    let done = server.wait_job_as(Some(alice), &job_id).await;
    assert_eq!(done["state"], "done", "{done}");
    let map_path = format!("/v1/maps/{}", done["map_id"].as_str().unwrap());
    let (s, map) = server.send_as(Some(alice), "GET", &map_path, None).await;
    assert_eq!(s, StatusCode::OK, "{map}");
    assert_eq!(server.metric_total("irs_map_builds_total").await, 1.0);
    let resumed_rows = server.metric_total("irs_map_rows_resumed_total").await;
    assert!(resumed_rows >= 10.0, "{resumed_rows} rows copied");
    let left: Vec<_> = std::fs::read_dir(dir.join("checkpoints"))
        .unwrap()
        .collect();
    assert!(
        left.is_empty(),
        "the checkpoint went with the build: {left:?}"
    );
    drop(server);
    let fresh = start(&[]);
    let (s, job) = fresh.post("/v1/maps", rate_request("resumed")).await;
    assert_eq!(s, StatusCode::ACCEPTED, "{job}");
    let built = fresh.wait_job(job["job_id"].as_str().unwrap()).await;
    let (_, whole) = fresh
        .get(&format!("/v1/maps/{}", built["map_id"].as_str().unwrap()))
        .await;
    assert!(
        map["values"].is_array() && map["upper_bound"].is_array(),
        "{map}"
    );
    assert_eq!(map["values"], whole["values"], "resumed = never stopped");
    assert_eq!(map["upper_bound"], whole["upper_bound"]);
    drop(fresh);
    // Done now: a third start resumes nothing.
    let server = start_binary(&flags);
    let (_, again) = server.send_as(Some(alice), "GET", &job_path, None).await;
    assert_eq!(again["state"], "done", "{again}");
    assert_eq!(server.metric_total("irs_map_builds_total").await, 0.0);
    drop(server);
    let _ = std::fs::remove_dir_all(&dir);
}

/// `--data-dir`: API scenarios (with their owners), built maps and finished jobs survive a
/// SIGKILL and a restart; nothing is built again, and a damaged map file is never served.
#[tokio::test]
async fn a_data_dir_survives_a_kill_and_serves_without_rebuilding() {
    let dir = std::env::temp_dir().join(format!("irs-data-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let (alice, bob) = ("alice-token-0123456789", "bob-token-0123456789ab");
    let tokens = format!("{alice},{bob}");
    let flags = ["--data-dir", dir.to_str().unwrap(), "--api-tokens", &tokens];
    let server = start_binary(&flags);
    let doc = scenario("small-test.json", |v| v["name"] = "persisted".into());
    let (s, created) = server
        .send_as(Some(alice), "POST", "/v1/scenarios", Some(doc))
        .await;
    assert_eq!(s, StatusCode::CREATED, "{created}");
    let sid = created["id"].as_str().unwrap().to_string();
    let mut map_ids = Vec::new();
    let mut job_id = None;
    for request in [
        json!({"scenario_id": sid, "kind": "gain"}),
        json!({"scenario_id": sid, "kind": "gain", "phases": 1}),
        json!({"scenario_id": sid, "kind": "rate"}),
    ] {
        let (s, answer) = server
            .send_as(Some(alice), "POST", "/v1/maps", Some(request))
            .await;
        assert!(s.is_success(), "{answer}");
        let map_id = if let Some(job) = answer["job_id"].as_str() {
            let job = server.wait_job_as(Some(alice), job).await;
            assert_eq!(job["state"], "done", "{job}");
            job_id = Some(job["job_id"].as_str().unwrap().to_string());
            job["map_id"].as_str().unwrap().to_string()
        } else {
            answer["map_id"].as_str().unwrap().to_string()
        };
        map_ids.push(map_id);
    }
    let path_request =
        json!({"map_id": map_ids[0], "start": [0.5, 0.5], "goal": [3.5, 3.5], "threshold": "max"});
    let (s, before) = server
        .send_as(Some(alice), "POST", "/v1/paths", Some(path_request.clone()))
        .await;
    assert_eq!(s, StatusCode::OK, "{before}");
    let builds = server.metric_total("irs_map_builds_total").await;
    assert_eq!(builds, 3.0, "three maps were built");
    drop(server); // SIGKILL: no shutdown hook runs.

    // The bits map's file torn in the middle, as a crash during a plain write would leave it.
    let torn = dir.join("maps").join(format!("{}.rec", map_ids[1]));
    let bytes = std::fs::read(&torn).unwrap();
    std::fs::write(&torn, &bytes[..bytes.len() / 2]).unwrap();

    let server = start_binary(&flags);
    let (_, mine) = server
        .send_as(Some(alice), "GET", "/v1/scenarios", None)
        .await;
    assert!(
        mine.to_string().contains(&sid),
        "alice still owns it: {mine}"
    );
    let (_, theirs) = server
        .send_as(Some(bob), "GET", "/v1/scenarios", None)
        .await;
    assert!(
        !theirs.to_string().contains(&sid),
        "bob still does not: {theirs}"
    );
    for map_id in [&map_ids[0], &map_ids[2]] {
        let path = format!("/v1/maps/{map_id}");
        let (s, map) = server.send_as(Some(alice), "GET", &path, None).await;
        assert_eq!(s, StatusCode::OK, "alice's claim survived: {map}");
        let (s, map) = server.send_as(Some(bob), "GET", &path, None).await;
        assert_eq!(s, StatusCode::NOT_FOUND, "bob still has none: {map}");
    }
    let (s, after) = server
        .send_as(Some(alice), "POST", "/v1/paths", Some(path_request))
        .await;
    assert_eq!(s, StatusCode::OK, "{after}");
    assert_eq!(after["waypoints"], before["waypoints"]);
    let (s, gone) = server
        .send_as(
            Some(alice),
            "GET",
            &format!("/v1/maps/{}", map_ids[1]),
            None,
        )
        .await;
    assert_eq!(
        s,
        StatusCode::NOT_FOUND,
        "a torn file is not served: {gone}"
    );
    assert!(server.metric_total("irs_store_corrupt_total").await >= 1.0);
    let job_id = job_id.expect("the rate map was a job");
    let (s, job) = server
        .send_as(Some(alice), "GET", &format!("/v1/jobs/{job_id}"), None)
        .await;
    assert_eq!(s, StatusCode::OK, "{job}");
    assert_eq!(job["state"], "done");
    assert_eq!(job["map_id"], map_ids[2].as_str());
    assert_eq!(
        server.metric_total("irs_map_builds_total").await,
        0.0,
        "nothing was built again"
    );
    // Deleting the scenario removes its maps from the disk too.
    let (s, _) = server
        .send_as(Some(alice), "DELETE", &format!("/v1/scenarios/{sid}"), None)
        .await;
    assert_eq!(s, StatusCode::NO_CONTENT);
    assert!(
        !dir.join("maps")
            .join(format!("{}.rec", map_ids[0]))
            .exists()
    );
    assert!(!dir.join("scenarios").join(format!("{sid}.rec")).exists());
    drop(server);
    let _ = std::fs::remove_dir_all(&dir);
}

fn mkfifo(path: &std::path::Path) {
    let made = Command::new("mkfifo").arg(path).status().expect("mkfifo");
    assert!(made.success(), "mkfifo {}", path.display());
}

/// A request URI past the documented limit, and a JSON body repeating a key (at the top, in a
/// nested object, in a scenario inside the body), are refused as problem+json naming why.
#[tokio::test]
async fn long_uris_and_repeated_keys_are_refused_as_problems() {
    let server = start(&[]);
    let long = format!("/v1/maps?cursor={}", "a".repeat(9000));
    let resp = server
        .client
        .get(format!("{}{long}", server.base))
        .send()
        .await
        .unwrap();
    assert_eq!(
        resp.headers()["content-type"],
        "application/problem+json",
        "not hyper's bare 414"
    );
    let status = resp.status();
    let body: Value = resp.json().await.unwrap();
    problem(status, &body, StatusCode::URI_TOO_LONG, "uri_too_long");
    assert_eq!(body["limit"], 8192);
    // Just under the limit, the request is read (and refused for its cursor, not its length).
    let (s, _) = server
        .get(&format!("/v1/maps?cursor={}", "a".repeat(8000)))
        .await;
    assert_eq!(s, StatusCode::UNPROCESSABLE_ENTITY);

    let small = std::fs::read_to_string(format!("{}/scenarios/small-test.json", root())).unwrap();
    let id = server.scenario_id("small-test").await;
    let cases = [
        (
            "/v1/scenarios",
            small.replacen('{', r#"{"name": "first", "#, 1),
            "$",
            "name",
        ),
        (
            "/v1/scenarios",
            small.replacen(r#""irs": {"#, r#""irs": {"nx_sub": 1000, "#, 1),
            "irs",
            "nx_sub",
        ),
        (
            "/v1/paths",
            format!(
                r#"{{"map": {{"scenario_id": "{id}", "kind": "gain", "kind": "rate"}}, "start": [0.5, 0.5], "goal": [5.5, 3.5], "threshold": "max"}}"#
            ),
            "map",
            "kind",
        ),
    ];
    for (route, body, field, key) in cases {
        let resp = server
            .client
            .post(format!("{}{route}", server.base))
            .header("content-type", "application/json")
            .body(body)
            .send()
            .await
            .unwrap();
        let status = resp.status();
        let answer: Value = resp.json().await.unwrap();
        problem(
            status,
            &answer,
            StatusCode::UNPROCESSABLE_ENTITY,
            "invalid_field",
        );
        assert_eq!(answer["field"], field, "{answer}");
        assert!(
            answer["detail"]
                .as_str()
                .unwrap()
                .contains(&format!("duplicate key `{key}`")),
            "{answer}"
        );
    }
}

/// One bad file in `--scenarios` (invalid, a FIFO, an image that is /dev/zero) is skipped,
/// not fatal: the others are served.
#[tokio::test]
async fn bad_scenario_files_are_skipped_and_the_rest_served() {
    let dir = std::env::temp_dir().join(format!("irs-preload-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::write(dir.join("broken.json"), r#"{"room": 1}"#).unwrap();
    mkfifo(&dir.join("fifo.json"));
    std::fs::write(
        dir.join("zero.yaml"),
        "image: /dev/zero\nresolution: 0.05\norigin: [0, 0, 0]\nnegate: 0\n\
         occupied_thresh: 0.65\nfree_thresh: 0.25\n",
    )
    .unwrap();
    let zero = scenario("small-test.json", |v| {
        v["name"] = "zero".into();
        v["floor_plan"] = json!({"map": "zero.yaml"});
    });
    std::fs::write(dir.join("zero.json"), zero.to_string()).unwrap();
    let good = scenario("small-test.json", |v| v["name"] = "preloaded".into());
    std::fs::write(dir.join("good.json"), good.to_string()).unwrap();
    let server = start_with_scenarios(dir.to_str().unwrap(), &[]);
    let (s, ready) = tokio::time::timeout(Duration::from_secs(20), server.get("/readyz"))
        .await
        .expect("start-up does not wait on the FIFO or /dev/zero");
    assert_eq!(s, StatusCode::OK, "{ready}");
    assert_eq!(ready["scenarios"], 4, "the built-in three and good.json");
    server.scenario_id("preloaded").await;
    drop(server);
    let _ = std::fs::remove_dir_all(&dir);
}

/// A data directory holding FIFOs under record names starts without waiting on them; one that
/// cannot be written starts too, serves, and `/readyz` stays 200 (a load balancer keeps routing
/// to it) but says `degraded` and why, until it can be written again.
#[tokio::test]
async fn an_unwritable_data_dir_starts_degraded_and_readyz_says_why() {
    let dir = std::env::temp_dir().join(format!("irs-unwritable-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    for sub in ["maps", "scenarios"] {
        std::fs::create_dir_all(dir.join(sub)).unwrap();
    }
    mkfifo(&dir.join("maps").join(format!("{}.rec", "ab".repeat(16))));
    mkfifo(&dir.join("scenarios").join("cd34.rec"));
    // A file where the jobs directory should be: every write there fails, as on a full disk
    // (permissions would not stop a test run as root).
    std::fs::write(dir.join("jobs"), b"in the way").unwrap();
    let server = start(&["--data-dir", dir.to_str().unwrap()]);
    let (s, ready) = tokio::time::timeout(Duration::from_secs(20), server.get("/readyz"))
        .await
        .expect("start-up does not wait on the FIFOs");
    assert_eq!(s, StatusCode::OK, "{ready}");
    assert_eq!(ready["status"], "degraded", "{ready}");
    let degraded = ready["degraded"].as_array().unwrap();
    assert_eq!(degraded.len(), 1, "{ready}");
    assert_eq!(degraded[0]["component"], "data_dir");
    assert_eq!(degraded[0]["code"], "data_dir_unwritable");
    assert!(
        degraded[0]["reason"].as_str().unwrap().contains("jobs"),
        "{ready}"
    );
    let (s, _) = server.get("/v1/scenarios").await;
    assert_eq!(s, StatusCode::OK, "it serves all the same");
    // Writable again: ready within a probe period (5 s).
    std::fs::remove_file(dir.join("jobs")).unwrap();
    std::fs::create_dir(dir.join("jobs")).unwrap();
    let deadline = Instant::now() + Duration::from_secs(15);
    loop {
        let (s, ready) = server.get("/readyz").await;
        assert_eq!(s, StatusCode::OK, "{ready}");
        if ready["status"] == "ready" {
            assert_eq!(ready["degraded"], json!([]));
            break;
        }
        assert!(Instant::now() < deadline, "still degraded: {ready}");
        tokio::time::sleep(Duration::from_millis(200)).await;
    }
    drop(server);
    let _ = std::fs::remove_dir_all(&dir);
}

/// Two tenants with tokens.
const ALICE: &str = "alice-token-0123456789";
const BOB: &str = "bob-token-0123456789ab";

/// Who calls in the tenants' matrix.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Who {
    Anonymous,
    Alice,
    Bob,
}

impl Who {
    fn token(self) -> Option<&'static str> {
        match self {
            Who::Anonymous => None,
            Who::Alice => Some(ALICE),
            Who::Bob => Some(BOB),
        }
    }
}

/// A route graph travels with its scenario: refused whole when malformed (naming the feature
/// and field, nothing registered), scored on a map as a report or as the graph itself
/// annotated, and routed on with a threshold, every answer format included.
#[tokio::test]
async fn route_graphs_are_scored_and_routed_over_http() {
    let server = start(&[]);
    let aws: Value = serde_json::from_str(
        &std::fs::read_to_string(format!(
            "{}/tests/data/route_graphs/nav2/aws_graph.geojson",
            root()
        ))
        .unwrap(),
    )
    .unwrap();
    let (_, before) = server.get("/v1/scenarios").await;
    let mut broken = aws.clone();
    broken["features"][45]["properties"]["endid"] = json!(400);
    let (s, body) = server
        .post(
            "/v1/scenarios",
            scenario("paper-single-user.json", |v| {
                v["name"] = "graph".into();
                v["route_graph"] = json!({"format": "nav2_geojson", "graph": broken});
            }),
        )
        .await;
    problem(
        s,
        &body,
        StatusCode::UNPROCESSABLE_ENTITY,
        "invalid_scenario",
    );
    assert_eq!(
        body["field"], "route_graph.graph.features[45].properties.endid",
        "{body}"
    );
    let (_, after) = server.get("/v1/scenarios").await;
    assert_eq!(before, after, "a refused graph registers nothing");

    let document = scenario("paper-single-user.json", |v| {
        v["name"] = "graph".into();
        v["route_graph"] = json!({"format": "nav2_geojson", "graph": aws});
    });
    let (s, created) = server.post("/v1/scenarios", document).await;
    assert_eq!(s, StatusCode::CREATED, "{created}");
    let sid = created["id"].as_str().unwrap().to_string();
    let (_, read) = server.get(&format!("/v1/scenarios/{sid}")).await;
    assert_eq!(read["scenario"]["route_graph"]["graph"], aws);
    let (s, map) = server
        .post("/v1/maps", json!({"scenario_id": sid, "kind": "gain"}))
        .await;
    assert_eq!(s, StatusCode::OK);
    let mid = map["map_id"].as_str().unwrap();

    let (s, report) = server.get(&format!("/v1/maps/{mid}/route-graph")).await;
    assert_eq!(s, StatusCode::OK, "{report}");
    let edges = report["edges"].as_array().unwrap();
    assert_eq!((report["nodes"].as_u64(), edges.len()), (Some(40), 84));
    assert!(report["closed_edges"].as_array().unwrap().iter().all(|id| {
        edges
            .iter()
            .any(|e| &e["id"] == id && e["worst_value"].is_null())
    }));
    let mut worst: Vec<f64> = edges
        .iter()
        .filter_map(|e| e["worst_value"].as_f64())
        .collect();
    worst.sort_by(f64::total_cmp);
    let threshold = worst[worst.len() / 2];
    let (s, report) = server
        .get(&format!(
            "/v1/maps/{mid}/route-graph?threshold={threshold}&penalty_band=2"
        ))
        .await;
    assert_eq!(s, StatusCode::OK, "{report}");
    let closed = report["closed_edges"].as_array().unwrap();
    assert!(closed.len() >= 84 / 2 - 1, "{}", closed.len());
    assert_eq!(
        report["closure_request"]["request"]["closed_edges"]
            .as_array()
            .unwrap()
            .len(),
        closed.len()
    );
    let response = server
        .client
        .get(format!(
            "{}/v1/maps/{mid}/route-graph?threshold={threshold}&format=graph",
            server.base
        ))
        .send()
        .await
        .unwrap();
    assert_eq!(response.headers()["content-type"], "application/geo+json");
    let graph: Value = response.json().await.unwrap();
    assert_eq!(
        graph["features"].as_array().unwrap().len(),
        aws["features"].as_array().unwrap().len()
    );
    assert_eq!(
        &graph["irs_planner"]["closed_edges"],
        &report["closed_edges"]
    );
    for (query, field) in [
        ("penalty_band=2", "penalty_band"),
        ("threshold=x", "threshold"),
        ("format=svg", "format"),
        ("unit=furlongs", "unit"),
        ("colour=red", "colour"),
    ] {
        let (s, body) = server
            .get(&format!("/v1/maps/{mid}/route-graph?{query}"))
            .await;
        assert_eq!(s, StatusCode::UNPROCESSABLE_ENTITY, "{query}: {body}");
        assert_eq!(body["field"], field, "{body}");
    }
    // The paper floor's own map has no graph to score or route on, but makes one: a roadmap of
    // its feasible region, which attached as its route graph is every edge open.
    let paper = server.paper_gain_map_url().await;
    let paper_id = paper.rsplit('/').next().unwrap();
    let response = server
        .client
        .get(format!(
            "{paper}/roadmap?spacing_m=2&threshold=-70&format=rmf_nav_graph"
        ))
        .send()
        .await
        .unwrap();
    assert_eq!(response.status(), StatusCode::OK);
    assert_eq!(response.headers()["content-type"], "application/yaml");
    let yaml = response.text().await.unwrap();
    assert!(
        yaml.contains("levels:") && yaml.contains("lanes:"),
        "{yaml}"
    );
    let (s, roadmap) = server
        .get(&format!(
            "/v1/maps/{paper_id}/roadmap?spacing_m=2&threshold=-70"
        ))
        .await;
    assert_eq!(s, StatusCode::OK);
    let (s, created) = server
        .post(
            "/v1/scenarios",
            scenario("paper-single-user.json", |v| {
                v["name"] = "roadmap".into();
                v["route_graph"] = json!({"format": "nav2_geojson", "graph": roadmap});
            }),
        )
        .await;
    assert_eq!(s, StatusCode::CREATED, "{created}");
    let (_, map) = server
        .post(
            "/v1/maps",
            json!({"scenario_id": created["id"], "kind": "gain"}),
        )
        .await;
    let (s, report) = server
        .get(&format!(
            "/v1/maps/{}/route-graph?threshold=-70",
            map["map_id"].as_str().unwrap()
        ))
        .await;
    assert_eq!(s, StatusCode::OK, "{report}");
    assert!(report["edges"].as_array().unwrap().len() > 100);
    assert_eq!(report["closed_edges"], json!([]));
    for (query, field) in [
        ("threshold=-70", "spacing_m"),
        ("spacing_m=0.1", "spacing_m"),
        ("spacing_m=2&format=dxf", "format"),
        ("spacing_m=2&penalty_band=1", "penalty_band"),
        ("spacing_m=2&threshold=100", "threshold"),
    ] {
        let (s, body) = server
            .get(&format!("/v1/maps/{paper_id}/roadmap?{query}"))
            .await;
        assert_eq!(s, StatusCode::UNPROCESSABLE_ENTITY, "{query}: {body}");
        assert_eq!(body["field"], field, "{body}");
    }
    let (s, body) = server
        .get(&format!("/v1/maps/{paper_id}/route-graph"))
        .await;
    assert_eq!(s, StatusCode::UNPROCESSABLE_ENTITY, "{body}");
    assert_eq!(body["field"], "route_graph", "{body}");
    let (s, body) = server
        .post(
            "/v1/paths",
            json!({"map_id": paper_id, "start": [-5.5, -8.5], "goal": [5.5, 8.65],
            "threshold": "max", "path_shape": "route_graph"}),
        )
        .await;
    assert_eq!(s, StatusCode::UNPROCESSABLE_ENTITY, "{body}");
    assert_eq!(body["field"], "path_shape", "{body}");

    // A route on the graph: nearest nodes, vertices at nodes, every waypoint's cell at the
    // threshold; the largest threshold found by the widest path.
    let query = json!({"map_id": mid, "start": [-6.0, -9.0], "goal": [6.0, -2.4],
        "threshold": "max", "path_shape": "route_graph"});
    let (s, path) = server.post("/v1/paths", query.clone()).await;
    assert_eq!(s, StatusCode::OK, "{path}");
    assert_eq!(path["path_shape"], "route_graph");
    assert!(path["feasible"].as_bool().unwrap(), "{path}");
    assert_eq!(
        (&path["start"]["node"], &path["goal"]["node"]),
        (&json!("29"), &json!("35"))
    );
    let t = path["threshold"].as_f64().unwrap();
    assert!(
        path["waypoints"]
            .as_array()
            .unwrap()
            .iter()
            .all(|w| w["value"].as_f64().unwrap() >= t)
    );
    let mut order = query.clone();
    order["order"] = json!({"order_id": "graph-1"});
    let response = server
        .client
        .post(format!("{}/v1/paths", server.base))
        .header("content-type", "application/json")
        .header("accept", "application/vnd.vda5050.order+json")
        .body(order.to_string())
        .send()
        .await
        .unwrap();
    assert_eq!(response.status(), StatusCode::OK);
    let order: Value = response.json().await.unwrap();
    assert_eq!(
        order["nodes"].as_array().unwrap().len(),
        path["vertices"].as_array().unwrap().len()
    );
    let mut above = query.clone();
    above["threshold"] = json!(t + 0.01);
    let (s, none) = server.post("/v1/paths", above).await;
    assert_eq!(s, StatusCode::OK);
    assert_eq!(none["reason"], "disconnected", "{none}");
    let mut tolerant = query;
    tolerant["tolerance_m"] = json!(1.0);
    let (s, body) = server.post("/v1/paths", tolerant).await;
    assert_eq!(s, StatusCode::UNPROCESSABLE_ENTITY, "{body}");
    assert_eq!(body["field"], "tolerance_m", "{body}");
}

/// Tokens on: every route of openapi.yaml (read from it, so a new route cannot be left out),
/// with every method, called by nobody, by the tenant that made the objects it names (alice)
/// and by another (bob). Alice gets her answers; bob and anonymous callers get 404 for
/// alice's objects, exactly as for ids that do not exist (never 403), and anonymous writes 401;
/// listings show each caller only its own.
#[tokio::test]
async fn tenants_see_and_touch_only_their_own() {
    let server = start(&["--api-tokens", &format!("{ALICE},{BOB}"), "--workers", "1"]);
    let as_alice = |method: &'static str, path: String, body: Option<Value>| {
        let server = &server;
        async move { server.send_as(Some(ALICE), method, &path, body).await }
    };
    let doc = scenario("small-test.json", |v| {
        v["name"] = "alice's floor".into();
        v["route_graph"] = two_node_graph([0.5, 0.5], [5.5, 0.5]);
    });
    let (s, created) = as_alice("POST", "/v1/scenarios".into(), Some(doc.clone())).await;
    assert_eq!(s, StatusCode::CREATED, "{created}");
    let sid = created["id"].as_str().unwrap().to_string();
    let (s, map) = as_alice(
        "POST",
        "/v1/maps".into(),
        Some(json!({"scenario_id": sid, "kind": "gain"})),
    )
    .await;
    assert_eq!(s, StatusCode::OK, "{map}");
    let mid = map["map_id"].as_str().unwrap().to_string();
    let (s, job) = as_alice(
        "POST",
        "/v1/maps".into(),
        Some(long_rate_request(fine_multi_user("alice's job"), "noma")),
    )
    .await;
    assert_eq!(s, StatusCode::ACCEPTED, "{job}");
    let jid = job["job_id"].as_str().unwrap().to_string();
    let placement = json!({"scenario_id": sid,
        "candidates": {"walls": [{"from": [0, 0], "to": [6, 0]}], "step_m": 1},
        "objective": {"kind": "coverage", "threshold": -80}, "keep": 1});
    let (s, placed) = as_alice("POST", "/v1/placements".into(), Some(placement.clone())).await;
    assert_eq!(s, StatusCode::OK, "{placed}");
    let pid = placed["placement_id"].as_str().unwrap().to_string();
    // A Monte Carlo check long enough to be a job (on a built-in floor, everybody's).
    let paper = server.scenario_id("paper-single-user").await;
    let (s, checking) = as_alice(
        "POST",
        "/v1/paths".into(),
        Some(
            json!({"map": {"scenario_id": paper, "kind": "gain"}, "start": [-10, 0],
                    "goal": [10, 0], "threshold": -64, "monte_carlo_draws": 2500}),
        ),
    )
    .await;
    assert_eq!(s, StatusCode::ACCEPTED, "{checking}");
    let cid = checking["job_id"].as_str().unwrap().to_string();

    let path_query =
        json!({"map_id": mid, "start": [0.5, 0.5], "goal": [5.5, 0.5], "threshold": "max"});
    let sweep =
        json!({"map_id": mid, "start": [0.5, 0.5], "goal": [5.5, 0.5], "thresholds": [-90, -80]});
    let fleet = json!({"map_id": mid, "robots": [{"start": [0.5, 0.5], "goal": [5.5, 0.5], "threshold": -120}]});
    // A fleet plan asked for as a job (`Prefer: respond-async`), behind her rate map on the
    // one worker.
    let response = server
        .client
        .post(format!("{}/v1/fleet-plans", server.base))
        .bearer_auth(ALICE)
        .header("content-type", "application/json")
        .header("prefer", "respond-async")
        .body(fleet.to_string())
        .send()
        .await
        .unwrap();
    assert_eq!(response.status(), StatusCode::ACCEPTED);
    let fid = response.json::<Value>().await.unwrap()["job_id"]
        .as_str()
        .unwrap()
        .to_string();
    /// What a route is to the matrix: everybody's, a listing, a registration, or a route on
    /// (or naming) alice's objects.
    #[derive(Debug, PartialEq)]
    enum Class {
        Everybody,
        Listing,
        Registration,
        Alices,
    }
    // Reads first, then writes, then deletions, so each call meets alice's objects intact.
    let mut routes = documented_routes();
    let phase = |m: &str| {
        ["get", "post", "delete"]
            .iter()
            .position(|p| *p == m)
            .unwrap()
    };
    routes.sort_by_key(|(m, _)| phase(m));
    for (method, route) in routes {
        let (class, path, body): (Class, String, Option<Value>) =
            match (method.as_str(), route.as_str()) {
                (
                    "get",
                    "/" | "/viewer/viewer.js" | "/viewer/viewer.css" | "/healthz" | "/readyz"
                    | "/version" | "/metrics",
                ) => (Class::Everybody, route.clone(), None),
                ("get", "/v1/scenarios" | "/v1/maps" | "/v1/jobs") => {
                    (Class::Listing, route.clone(), None)
                }
                ("post", "/v1/scenarios") => (Class::Registration, route.clone(), None),
                ("get" | "delete", "/v1/scenarios/{scenario_id}") => {
                    (Class::Alices, format!("/v1/scenarios/{sid}"), None)
                }
                ("post", "/v1/maps") => (
                    Class::Alices,
                    route.clone(),
                    Some(json!({"scenario_id": sid, "kind": "gain"})),
                ),
                ("get" | "delete", "/v1/maps/{map_id}") => {
                    (Class::Alices, format!("/v1/maps/{mid}"), None)
                }
                ("get", "/v1/maps/{map_id}/coverage") => (
                    Class::Alices,
                    format!("/v1/maps/{mid}/coverage?threshold=-80"),
                    None,
                ),
                ("get", "/v1/maps/{map_id}/image.png") => {
                    (Class::Alices, format!("/v1/maps/{mid}/image.png"), None)
                }
                ("get", "/v1/maps/{map_id}/nav2-mask") => (
                    Class::Alices,
                    format!("/v1/maps/{mid}/nav2-mask?threshold=-80"),
                    None,
                ),
                ("get", "/v1/maps/{map_id}/values.npy") => {
                    (Class::Alices, format!("/v1/maps/{mid}/values.npy"), None)
                }
                ("get", "/v1/maps/{map_id}/zone-set") => (
                    Class::Alices,
                    format!("/v1/maps/{mid}/zone-set?threshold=-80"),
                    None,
                ),
                ("get", "/v1/maps/{map_id}/roadmap") => (
                    Class::Alices,
                    format!("/v1/maps/{mid}/roadmap?spacing_m=1"),
                    None,
                ),
                ("get", "/v1/maps/{map_id}/route-graph") => (
                    Class::Alices,
                    format!("/v1/maps/{mid}/route-graph?threshold=-80"),
                    None,
                ),
                ("get" | "delete", "/v1/jobs/{job_id}") => {
                    (Class::Alices, format!("/v1/jobs/{jid}"), None)
                }
                ("post", "/v1/placements") => {
                    (Class::Alices, route.clone(), Some(placement.clone()))
                }
                ("get", "/v1/placements/{placement_id}") => {
                    (Class::Alices, format!("/v1/placements/{pid}"), None)
                }
                ("get", "/v1/checks/{check_id}") => {
                    (Class::Alices, format!("/v1/checks/{cid}"), None)
                }
                ("post", "/v1/paths") => (Class::Alices, route.clone(), Some(path_query.clone())),
                ("post", "/v1/sweeps") => (Class::Alices, route.clone(), Some(sweep.clone())),
                ("post", "/v1/fleet-plans") => (Class::Alices, route.clone(), Some(fleet.clone())),
                ("get", "/v1/fleet-plans/{plan_id}") => {
                    (Class::Alices, format!("/v1/fleet-plans/{fid}"), None)
                }
                other => panic!("{other:?}: a route the tenants' matrix does not know; add it"),
            };
        let method = method.to_uppercase();
        // Alice last, so her deletion does not change what the others meet.
        for who in [Who::Anonymous, Who::Bob, Who::Alice] {
            let body = match class {
                // Each registers a document of its own (the same document is checked below).
                Class::Registration => Some(scenario("small-test.json", |v| {
                    v["name"] = format!("{who:?}'s own").into()
                })),
                _ => body.clone(),
            };
            let (status, answer) = server.send_as(who.token(), &method, &path, body).await;
            let writes = method != "GET";
            let expected = match (&class, who) {
                (Class::Everybody | Class::Listing, _) => {
                    assert!(
                        status.is_success(),
                        "{who:?} {method} {path}: {status} {answer}"
                    );
                    continue;
                }
                (_, Who::Anonymous) if writes => StatusCode::UNAUTHORIZED,
                // Her job may have finished by now: 409, the state of a job she can see.
                (Class::Alices, Who::Alice)
                    if method == "DELETE"
                        && path.starts_with("/v1/jobs/")
                        && status == StatusCode::CONFLICT =>
                {
                    assert_eq!(answer["code"], "job_finished", "{answer}");
                    continue;
                }
                // Her check may still be queued behind her rate map: 409, the state she can see.
                (Class::Alices, Who::Alice)
                    if path.starts_with("/v1/checks/") && status == StatusCode::CONFLICT =>
                {
                    assert_eq!(answer["code"], "check_not_ready", "{answer}");
                    continue;
                }
                (Class::Alices, Who::Alice)
                    if path.starts_with("/v1/fleet-plans/") && status == StatusCode::CONFLICT =>
                {
                    assert_eq!(answer["code"], "fleet_plan_not_ready", "{answer}");
                    continue;
                }
                (Class::Registration, _) | (Class::Alices, Who::Alice) => {
                    assert!(
                        status.is_success(),
                        "{who:?} {method} {path}: {status} {answer}"
                    );
                    continue;
                }
                (Class::Alices, _) => StatusCode::NOT_FOUND,
            };
            assert_eq!(status, expected, "{who:?} {method} {path}: {answer}");
            let code = if expected == StatusCode::NOT_FOUND {
                "not_found"
            } else {
                "unauthorized"
            };
            problem(status, &answer, expected, code);
        }
        if class == Class::Listing {
            let mine = match path.as_str() {
                "/v1/scenarios" => &sid,
                "/v1/maps" => &mid,
                _ => &jid,
            };
            for (who, sees) in [
                (Who::Anonymous, false),
                (Who::Bob, false),
                (Who::Alice, true),
            ] {
                let (_, list) = server.send_as(who.token(), "GET", &path, None).await;
                let text = list.to_string();
                assert_eq!(text.contains(mine.as_str()), sees, "{who:?} {path}: {text}");
            }
        }
    }
    // The same document registered by bob is new to bob (201, as alice's was to her), and
    // then his as well as hers.
    let (s, again) = server
        .send_as(Some(BOB), "POST", "/v1/scenarios", Some(doc.clone()))
        .await;
    assert_eq!(s, StatusCode::CREATED, "{again}");
    let (s, _) = server
        .send_as(Some(BOB), "POST", "/v1/scenarios", Some(doc))
        .await;
    assert_eq!(s, StatusCode::OK, "bob's second registration is not new");
}

/// Two tenants asking for one map share its build; one tenant's cancel withdraws only its own
/// interest (the build goes on and the map is the other's), and the build stops only when the
/// last tenant lets go.
#[tokio::test]
async fn a_shared_build_serves_every_tenant_until_the_last_lets_go() {
    let server = start(&["--api-tokens", &format!("{ALICE},{BOB}"), "--workers", "1"]);
    let job_path = |id: &str| format!("/v1/jobs/{id}");
    // The worker is busy with alice's long build, so the shared one waits in the queue.
    let (s, blocker) = server
        .send_as(
            Some(ALICE),
            "POST",
            "/v1/maps",
            Some(long_rate_request(fine_multi_user("blocker"), "noma")),
        )
        .await;
    assert_eq!(s, StatusCode::ACCEPTED, "{blocker}");
    let shared = json!({"scenario": scenario("paper-multi-user.json", |_| {}), "kind": "rate", "access": "noma"});
    let (s, for_alice) = server
        .send_as(Some(ALICE), "POST", "/v1/maps", Some(shared.clone()))
        .await;
    assert_eq!(s, StatusCode::ACCEPTED, "{for_alice}");
    let (s, for_bob) = server
        .send_as(Some(BOB), "POST", "/v1/maps", Some(shared.clone()))
        .await;
    assert_eq!(s, StatusCode::ACCEPTED, "{for_bob}");
    assert_eq!(for_alice["job_id"], for_bob["job_id"], "one build for both");
    let jid = for_alice["job_id"].as_str().unwrap().to_string();
    let mid = for_alice["map_id"].as_str().unwrap().to_string();
    for who in [ALICE, BOB] {
        let (s, job) = server
            .send_as(Some(who), "GET", &job_path(&jid), None)
            .await;
        assert_eq!(s, StatusCode::OK, "{job}");
    }
    // Alice lets go: the job is no longer hers, and goes on for bob.
    let (s, _) = server
        .send_as(Some(ALICE), "DELETE", &job_path(&jid), None)
        .await;
    assert_eq!(s, StatusCode::ACCEPTED);
    let (s, _) = server
        .send_as(Some(ALICE), "GET", &job_path(&jid), None)
        .await;
    assert_eq!(s, StatusCode::NOT_FOUND, "alice withdrew");
    let (s, _) = server
        .send_as(Some(ALICE), "DELETE", &job_path(&jid), None)
        .await;
    assert_eq!(s, StatusCode::NOT_FOUND, "a withdrawal is made once");
    let blocker_id = blocker["job_id"].as_str().unwrap();
    let (s, _) = server
        .send_as(Some(ALICE), "DELETE", &job_path(blocker_id), None)
        .await;
    assert_eq!(
        s,
        StatusCode::ACCEPTED,
        "alice's own build, hers alone: it stops"
    );
    let done = server.wait_job_as(Some(BOB), &jid).await;
    assert_eq!(done["state"], "done", "bob's request was served: {done}");
    let map_path = format!("/v1/maps/{mid}");
    assert_eq!(
        server.send_as(Some(BOB), "GET", &map_path, None).await.0,
        StatusCode::OK
    );
    assert_eq!(
        server.send_as(Some(ALICE), "GET", &map_path, None).await.0,
        StatusCode::NOT_FOUND,
        "alice withdrew her claim with her interest"
    );
    let blocker_job = server.wait_job_as(Some(ALICE), blocker_id).await;
    assert_eq!(blocker_job["state"], "cancelled");

    // Both let go of a shared build: it stops with the last.
    let long = long_rate_request(fine_multi_user("both"), "noma");
    let (_, first) = server
        .send_as(Some(ALICE), "POST", "/v1/maps", Some(long.clone()))
        .await;
    let (_, second) = server
        .send_as(Some(BOB), "POST", "/v1/maps", Some(long))
        .await;
    assert_eq!(first["job_id"], second["job_id"]);
    let jid = first["job_id"].as_str().unwrap().to_string();
    let (s, _) = server
        .send_as(Some(BOB), "DELETE", &job_path(&jid), None)
        .await;
    assert_eq!(s, StatusCode::ACCEPTED);
    tokio::time::sleep(Duration::from_millis(200)).await;
    let (_, still) = server
        .send_as(Some(ALICE), "GET", &job_path(&jid), None)
        .await;
    assert!(
        ["queued", "running"].contains(&still["state"].as_str().unwrap()),
        "{still}"
    );
    let (s, _) = server
        .send_as(Some(ALICE), "DELETE", &job_path(&jid), None)
        .await;
    assert_eq!(s, StatusCode::ACCEPTED);
    let ended = server.wait_job_as(Some(ALICE), &jid).await;
    assert_eq!(ended["state"], "cancelled", "{ended}");
    assert_eq!(
        server.metric("irs_map_builds_total{kind=\"rate\"}").await,
        3.0,
        "one build per map"
    );
}

/// One tenant flooding the registry with inline scenarios evicts its own (with their maps);
/// with every slot pinned by its live jobs it is refused (507 `registry_full`, Retry-After),
/// and another tenant is still admitted.
#[tokio::test]
async fn a_full_registry_refuses_only_the_tenant_that_filled_it() {
    // Six scenarios, three of them built in: three API slots.
    let server = start(&[
        "--api-tokens",
        &format!("{ALICE},{BOB}"),
        "--max-scenarios",
        "6",
        "--workers",
        "1",
    ]);
    for k in 0..12 {
        let request = json!({"scenario": scenario("small-test.json", |v| v["name"] = format!("flood-{k}").into()), "kind": "gain"});
        let (s, answer) = server
            .send_as(Some(ALICE), "POST", "/v1/maps", Some(request))
            .await;
        assert_eq!(s, StatusCode::OK, "map {k} of the flood: {answer}");
    }
    assert!(server.metric_total("irs_scenarios_evicted_total").await >= 9.0);
    // Three long builds of alice's: every API slot is needed by a live job.
    let mut jobs = Vec::new();
    for k in 0..3 {
        let (s, job) = server
            .send_as(
                Some(ALICE),
                "POST",
                "/v1/maps",
                Some(long_rate_request(
                    fine_multi_user(&format!("pinned-{k}")),
                    "noma",
                )),
            )
            .await;
        assert_eq!(s, StatusCode::ACCEPTED, "{job}");
        jobs.push(job["job_id"].as_str().unwrap().to_string());
    }
    let one_more = json!({"scenario": scenario("small-test.json", |v| v["name"] = "one more".into()), "kind": "gain"});
    let refused = server
        .client
        .post(format!("{}/v1/maps", server.base))
        .bearer_auth(ALICE)
        .header("content-type", "application/json")
        .body(one_more.to_string())
        .send()
        .await
        .unwrap();
    assert_eq!(refused.headers()["retry-after"], "5");
    let status = refused.status();
    let body: Value = refused.json().await.unwrap();
    problem(
        status,
        &body,
        StatusCode::INSUFFICIENT_STORAGE,
        "registry_full",
    );
    let started = Instant::now();
    let bobs = scenario("small-test.json", |v| v["name"] = "bob's".into());
    let (s, created) = server
        .send_as(Some(BOB), "POST", "/v1/scenarios", Some(bobs))
        .await;
    assert_eq!(s, StatusCode::CREATED, "bob is not locked out: {created}");
    assert!(started.elapsed() < Duration::from_secs(2));
    assert_eq!(
        server
            .metric("irs_scenarios_refused_total{why=\"over_share\"}")
            .await,
        1.0
    );
    for job in jobs {
        server
            .send_as(Some(ALICE), "DELETE", &format!("/v1/jobs/{job}"), None)
            .await;
    }
}

/// A Monte Carlo check estimated over 2 s of CPU is a job (kind `check`): its result is read
/// at its `result_href` once done, it shows progress, it can be cancelled, and the answer is
/// the path answer with the report (as the synchronous form answers smaller checks).
#[tokio::test]
async fn long_monte_carlo_checks_are_jobs_with_progress_and_cancel() {
    let server = start(&["--workers", "1"]);
    let id = server.scenario_id("paper-single-user").await;
    let query = |draws: u64| {
        json!({"map": {"scenario_id": id, "kind": "gain"}, "start": [-10, 0], "goal": [10, 0],
               "threshold": -64, "monte_carlo_draws": draws, "seed": 7})
    };
    // ~41 waypoints × 1 200 elements: 100 draws are milliseconds, answered at once.
    let (status, small) = server.post("/v1/paths", query(100)).await;
    assert_eq!(status, StatusCode::OK, "{small}");
    assert!(small["monte_carlo"].is_object(), "{small}");

    // 40 000 draws are estimated at ~40 s: a job, cancelled once it has started.
    let (status, job) = server.post("/v1/paths", query(40_000)).await;
    assert_eq!(status, StatusCode::ACCEPTED, "{job}");
    assert_eq!(job["kind"], "check");
    let job_id = job["job_id"].as_str().unwrap().to_string();
    assert_eq!(job["result_href"], format!("/v1/checks/{job_id}"));
    let (status, body) = server.get(&format!("/v1/checks/{job_id}")).await;
    problem(status, &body, StatusCode::CONFLICT, "check_not_ready");
    let deadline = Instant::now() + Duration::from_secs(60);
    loop {
        let (_, j) = server.get(&format!("/v1/jobs/{job_id}")).await;
        if j["cells_done"].as_u64().unwrap() > 0 {
            assert!(j["cells_total"].as_u64().unwrap() > j["cells_done"].as_u64().unwrap());
            break;
        }
        assert!(Instant::now() < deadline, "the check never started: {j}");
        tokio::time::sleep(Duration::from_millis(10)).await;
    }
    let (status, _) = server
        .send("DELETE", &format!("/v1/jobs/{job_id}"), None)
        .await;
    assert_eq!(status, StatusCode::ACCEPTED);
    assert_eq!(server.wait_job(&job_id).await["state"], "cancelled");
    let (status, body) = server.get(&format!("/v1/checks/{job_id}")).await;
    problem(status, &body, StatusCode::CONFLICT, "job_finished");

    // 2 500 draws (~2.5 s estimated) run to the end: the path answer with the report.
    let (status, job) = server.post("/v1/paths", query(2_500)).await;
    assert_eq!(status, StatusCode::ACCEPTED, "{job}");
    let job_id = job["job_id"].as_str().unwrap();
    assert_eq!(server.wait_job(job_id).await["state"], "done");
    let (status, checked) = server.get(&format!("/v1/checks/{job_id}")).await;
    assert_eq!(status, StatusCode::OK, "{checked}");
    assert_eq!(checked["waypoints"], small["waypoints"], "the same path");
    let report = &checked["monte_carlo"];
    assert_eq!(report["draws"], 2_500, "{report}");
    assert!(checked["took_ms"].as_f64().unwrap() > 0.0);
    // Not someone else's: an unknown id, or a placement's, is not a check.
    let (status, body) = server
        .get("/v1/checks/00000000000000000000000000000000")
        .await;
    problem(status, &body, StatusCode::NOT_FOUND, "not_found");
}

/// Several robots planned at once: every robot's requirement is met at every step of the
/// timeline, the first robot drives its own path, and bad requests name their field.
#[tokio::test]
async fn fleets_are_planned_over_http() {
    let server = start(&[]);
    let (s, map) = server
        .post(
            "/v1/maps",
            json!({"scenario": scenario("paper-single-user.json", |_| {}), "kind": "gain"}),
        )
        .await;
    assert_eq!(s, StatusCode::OK, "{map}");
    let mid = map["map_id"].as_str().unwrap();
    let (s, single) = server
        .post(
            "/v1/paths",
            json!({"map_id": mid, "start": [-10, 0], "goal": [10, 0], "threshold": -75}),
        )
        .await;
    assert_eq!(s, StatusCode::OK, "{single}");
    let robots = json!([
        {"name": "first", "start": [-10, 0], "goal": [10, 0], "threshold": -75},
        {"start": [10, -9], "goal": [-10, -9], "threshold": -80},
        {"start": [-9, 9], "goal": [9, 9], "threshold": -70},
    ]);
    let (s, plan) = server
        .post("/v1/fleet-plans", json!({"map_id": mid, "robots": robots}))
        .await;
    assert_eq!(s, StatusCode::OK, "{plan}");
    assert_eq!(plan["names"], json!(["first", "robot-1", "robot-2"]));
    assert_eq!(plan["violations"], json!([]));
    assert_eq!(plan["robots"][0]["planned_by"], "alone");
    // The first robot's cells are the single path's.
    let mut cells: Vec<(f64, f64)> = plan["waypoints"][0]
        .as_array()
        .unwrap()
        .iter()
        .map(|w| (w["x"].as_f64().unwrap(), w["y"].as_f64().unwrap()))
        .collect();
    cells.dedup();
    let expected: Vec<(f64, f64)> = single["waypoints"]
        .as_array()
        .unwrap()
        .iter()
        .map(|w| (w["x"].as_f64().unwrap(), w["y"].as_f64().unwrap()))
        .collect();
    assert_eq!(cells, expected);
    for instant in plan["timeline"].as_array().unwrap() {
        for (r, at) in instant["robots"].as_array().unwrap().iter().enumerate() {
            if at.is_null() {
                continue;
            }
            assert_eq!(at["met"], true, "robot {r} at {instant}");
            let required = robots[r]["threshold"].as_f64().unwrap();
            assert!(at["value"].as_f64().unwrap() >= required - 1e-9);
        }
        assert_eq!(instant["phases"].as_array().unwrap().len(), 1);
    }
    // The single path given as a route, and a second robot planned around it, by NOMA.
    let route: Vec<Value> = single["waypoints"]
        .as_array()
        .unwrap()
        .iter()
        .map(|w| json!([w["x"], w["y"], w["time_s"]]))
        .collect();
    let (s, shared) = server
        .post(
            "/v1/fleet-plans",
            json!({"map_id": mid, "access": "noma", "unit": "bps_hz", "robots": [
                {"route": route, "threshold": 1.0},
                {"start": [10, -9], "goal": [-10, -9], "threshold": 1.0},
            ]}),
        )
        .await;
    assert_eq!(s, StatusCode::OK, "{shared}");
    assert_eq!(shared["robots"][0]["planned_by"], "given");
    assert_eq!(shared["access"], "noma");
    let both = shared["timeline"]
        .as_array()
        .unwrap()
        .iter()
        .find(|i| i["robots"].as_array().unwrap().iter().all(|r| !r.is_null()))
        .unwrap();
    let places: Vec<u64> = both["robots"]
        .as_array()
        .unwrap()
        .iter()
        .map(|r| r["decoded"].as_u64().unwrap())
        .collect();
    assert_eq!(places.iter().sum::<u64>(), 1, "{both}");
    for (body, field) in [
        (json!({"map_id": mid, "robots": []}), "robots"),
        (
            json!({"map_id": mid, "access": "oma", "unit": "dbm", "robots": [{"start": [0, 9], "goal": [0, -9], "threshold": -80}]}),
            "unit",
        ),
        (
            json!({"map_id": mid, "robots": [{"start": [0, 9], "threshold": -80}]}),
            "robots[0].goal",
        ),
        (
            json!({"map_id": mid, "robots": [{"route": [[0, 9, 1], [0, 8, 0.5]], "threshold": -80}]}),
            "robots[0].route[1]",
        ),
        (
            json!({"map_id": mid, "robots": [{"start": [50, 0], "goal": [0, 0], "threshold": -80}]}),
            "robots[0].start",
        ),
        (
            json!({"map_id": mid, "dt_s": 0, "robots": [{"start": [0, 9], "goal": [0, -9], "threshold": -80}]}),
            "dt_s",
        ),
        (
            json!({"map_id": mid, "dt_s": 1e-9, "robots": [{"start": [0, 9], "goal": [0, -9], "threshold": -80}]}),
            "dt_s",
        ),
        (
            json!({"map_id": mid, "horizon_s": 1e9, "robots": [{"start": [0, 9], "goal": [0, -9], "threshold": -80}]}),
            "horizon_s",
        ),
        (
            json!({"map_id": mid, "robots": [{"name": "a", "start": [0, 9], "goal": [0, -9], "threshold": -80}, {"name": "a", "start": [1, 9], "goal": [1, -9], "threshold": -80}]}),
            "robots[1].name",
        ),
    ] {
        let (s, problem_body) = server.post("/v1/fleet-plans", body).await;
        problem(
            s,
            &problem_body,
            StatusCode::UNPROCESSABLE_ENTITY,
            "invalid_field",
        );
        assert_eq!(problem_body["field"], field, "{problem_body}");
    }
}

/// `GET /v1/maps/{id}?unit=u`: the values and statistics in another unit, each the map's own
/// through the serving AP's link budget (dBm: gain + P_tx, one offset for one AP); a rate map
/// answers rates only; a map of two APs names the serving AP of every free cell.
#[tokio::test]
async fn map_bodies_answer_in_any_unit_with_the_serving_ap() {
    let server = start(&[]);
    let doc = scenario("paper-single-user.json", |_| {});
    let (s, map) = server
        .post("/v1/maps", json!({"scenario": doc.clone(), "kind": "gain"}))
        .await;
    assert_eq!(s, StatusCode::OK, "{map}");
    let mid = map["map_id"].as_str().unwrap();
    let (_, gain) = server.get(&format!("/v1/maps/{mid}")).await;
    let (s, dbm) = server.get(&format!("/v1/maps/{mid}?unit=dbm")).await;
    assert_eq!(s, StatusCode::OK, "{dbm}");
    assert_eq!(
        (gain["unit"].as_str(), dbm["unit"].as_str()),
        (Some("dB"), Some("dBm"))
    );
    assert!(gain.get("serving_ap").is_none(), "one AP: no serving grid");
    let p_tx = doc["ap"]["tx_power_dbm"].as_f64().unwrap();
    let (g, d) = (
        gain["values"].as_array().unwrap(),
        dbm["values"].as_array().unwrap(),
    );
    let mut compared = 0;
    for (gr, dr) in g.iter().zip(d) {
        for (gv, dv) in gr.as_array().unwrap().iter().zip(dr.as_array().unwrap()) {
            match (gv.as_f64(), dv.as_f64()) {
                (Some(gv), Some(dv)) => {
                    assert!((dv - (gv + p_tx)).abs() < 1e-9, "{gv} dB, {dv} dBm");
                    compared += 1;
                }
                (None, None) => {}
                other => panic!("null in one unit only: {other:?}"),
            }
        }
    }
    assert_eq!(
        compared,
        gain["stats"]["valued_cells"].as_u64().unwrap() as usize
    );
    let shift = dbm["stats"]["max"].as_f64().unwrap() - gain["stats"]["max"].as_f64().unwrap();
    assert!(
        (shift - p_tx).abs() < 1e-9,
        "the statistics are in the unit too"
    );
    let (s, body) = server.get(&format!("/v1/maps/{mid}?unit=furlongs")).await;
    assert_eq!(s, StatusCode::UNPROCESSABLE_ENTITY, "{body}");
    assert_eq!(body["field"], "unit");
    let (s, body) = server.get(&format!("/v1/maps/{mid}?units=dbm")).await;
    assert!(s.is_client_error(), "{s} {body}");
    assert_eq!(body["field"], "units");

    // A rate map answers rates only; in Mbit/s its bound and certificate are too.
    let rated = scenario("small-test.json", |v| v["ap"]["bandwidth_mhz"] = 20.into());
    let (s, job) = server
        .post(
            "/v1/maps",
            json!({"scenario": rated, "kind": "rate", "access": "noma"}),
        )
        .await;
    let rid = match s {
        StatusCode::ACCEPTED => server.wait_job(job["job_id"].as_str().unwrap()).await["map_id"]
            .as_str()
            .unwrap()
            .to_string(),
        _ => job["map_id"].as_str().unwrap().to_string(),
    };
    let (_, own) = server.get(&format!("/v1/maps/{rid}")).await;
    let (s, mbps) = server.get(&format!("/v1/maps/{rid}?unit=mbps")).await;
    assert_eq!(s, StatusCode::OK, "{mbps}");
    assert_eq!(mbps["unit"], "Mbit/s");
    for field in ["values", "upper_bound"] {
        for (a, b) in own[field]
            .as_array()
            .unwrap()
            .iter()
            .zip(mbps[field].as_array().unwrap())
        {
            for (a, b) in a.as_array().unwrap().iter().zip(b.as_array().unwrap()) {
                match (a.as_f64(), b.as_f64()) {
                    (Some(a), Some(b)) => assert!((b - 20.0 * a).abs() < 1e-9, "{field}: {a} {b}"),
                    (None, None) => {}
                    other => panic!("{field}: {other:?}"),
                }
            }
        }
    }
    let gap = |body: &Value| body["certificate"]["max_gap"].as_f64().unwrap();
    assert!((gap(&mbps) - 20.0 * gap(&own)).abs() < 1e-9);
    let (s, body) = server.get(&format!("/v1/maps/{rid}?unit=dbm")).await;
    assert_eq!(s, StatusCode::UNPROCESSABLE_ENTITY, "{body}");
    assert_eq!(body["field"], "unit");

    // Two APs, one in each half of the room: the serving one is the stronger, as the maps of
    // each AP alone say.
    let with_aps = |aps: Vec<[f64; 3]>| {
        scenario("paper-single-user.json", move |v| {
            let ap = v.as_object_mut().unwrap().remove("ap").unwrap();
            v["aps"] = aps
                .iter()
                .map(|p| {
                    let mut ap = ap.clone();
                    ap["position"] = json!(p);
                    ap
                })
                .collect();
        })
    };
    let (west, east) = ([-9.0, 0.0, 2.0], [9.0, 0.0, 2.0]);
    let mut bodies = Vec::new();
    for aps in [vec![west, east], vec![west], vec![east]] {
        let (s, map) = server
            .post(
                "/v1/maps",
                json!({"scenario": with_aps(aps), "kind": "gain"}),
            )
            .await;
        assert_eq!(s, StatusCode::OK, "{map}");
        let (_, body) = server
            .get(&format!("/v1/maps/{}", map["map_id"].as_str().unwrap()))
            .await;
        bodies.push(body);
    }
    let serving = bodies[0]["serving_ap"].as_array().unwrap();
    assert!(bodies[1].get("serving_ap").is_none());
    let mut served = [0, 0];
    for (i, row) in serving.iter().enumerate() {
        for (j, ap) in row.as_array().unwrap().iter().enumerate() {
            let value = |b: usize| bodies[b]["values"][i][j].as_f64();
            let Some(ap) = ap.as_u64() else {
                assert!(value(0).is_none(), "({i}, {j}) has a value but no AP");
                continue;
            };
            let (w, e) = (value(1).unwrap(), value(2).unwrap());
            if (w - e).abs() > 1e-9 {
                assert_eq!(ap, u64::from(e > w), "({i}, {j}): {w} dB west, {e} dB east");
            }
            assert!((value(0).unwrap() - w.max(e)).abs() < 1e-9);
            served[ap as usize] += 1;
        }
    }
    assert!(served[0] > 100 && served[1] > 100, "{served:?}");
}

/// A fleet plan over robots × cells beyond 4 × `--sync-cells` runs as a job (202, kind
/// `fleet`, progress in robots) whose plan, read at its `result_href`, is the plan a request
/// that waits gets; a bad field is still a 422 before any job; `Prefer: respond-async` asks for
/// a job whatever the size, and the job can be cancelled.
#[tokio::test]
async fn large_fleet_plans_run_as_jobs() {
    // The paper floor (1 681 cells) as a map answered at once; 3 robots × 1 681 > 4 × 1 200.
    let server = start(&["--sync-cells", "1200", "--workers", "1"]);
    let waiting = start(&[]);
    let map_request =
        json!({"scenario": scenario("paper-single-user.json", |_| {}), "kind": "gain"});
    let robots = json!([
        {"name": "first", "start": [-10, 0], "goal": [10, 0], "threshold": -75},
        {"start": [10, -9], "goal": [-10, -9], "threshold": -80},
        {"start": [-9, 9], "goal": [9, 9], "threshold": -70},
    ]);
    let (s, direct) = waiting
        .post(
            "/v1/fleet-plans",
            json!({"map": map_request.clone(), "robots": robots.clone()}),
        )
        .await;
    assert_eq!(s, StatusCode::OK, "{direct}");

    let (s, map) = server.post("/v1/maps", map_request).await;
    assert_eq!(
        s,
        StatusCode::ACCEPTED,
        "the map itself is a job here: {map}"
    );
    let map_job = server.wait_job(map["job_id"].as_str().unwrap()).await;
    assert_eq!(map_job["state"], "done", "{map_job}");
    let mid = map_job["map_id"].as_str().unwrap();
    for (body, field) in [
        (
            json!({"map_id": mid, "robots": [{"start": [50, 0], "goal": [0, 0], "threshold": -80}, {"start": [0, 9], "goal": [0, -9], "threshold": -80}, {"start": [1, 9], "goal": [1, -9], "threshold": -80}]}),
            "robots[0].start",
        ),
        (
            json!({"map_id": mid, "horizon_s": -1, "robots": robots.clone()}),
            "horizon_s",
        ),
    ] {
        let (s, problem_body) = server.post("/v1/fleet-plans", body).await;
        problem(
            s,
            &problem_body,
            StatusCode::UNPROCESSABLE_ENTITY,
            "invalid_field",
        );
        assert_eq!(problem_body["field"], field, "{problem_body}");
    }
    let (s, job) = server
        .post(
            "/v1/fleet-plans",
            json!({"map_id": mid, "robots": robots.clone()}),
        )
        .await;
    assert_eq!(s, StatusCode::ACCEPTED, "{job}");
    assert_eq!(job["kind"], "fleet");
    let job_id = job["job_id"].as_str().unwrap();
    assert_eq!(job["result_href"], format!("/v1/fleet-plans/{job_id}"));
    let done = server.wait_job(job_id).await;
    assert_eq!(done["state"], "done", "{done}");
    assert_eq!(
        (done["cells_done"].as_u64(), done["cells_total"].as_u64()),
        (Some(3), Some(3))
    );
    let (s, mut planned) = server.get(&format!("/v1/fleet-plans/{job_id}")).await;
    assert_eq!(s, StatusCode::OK, "{planned}");
    assert!(planned["took_ms"].as_f64().unwrap() >= 0.0);
    let mut direct = direct;
    for answer in [&mut planned, &mut direct] {
        answer.as_object_mut().unwrap().remove("took_ms");
    }
    assert_eq!(
        planned, direct,
        "the job's plan is the plan answered at once"
    );

    // Asked for as a job: 202 however small, and the preference said applied. A job queued
    // behind a long one on the single worker is cancelled before it runs.
    let slow = server
        .post(
            "/v1/maps",
            long_rate_request(fine_multi_user("a long build ahead"), "noma"),
        )
        .await;
    assert_eq!(slow.0, StatusCode::ACCEPTED, "{}", slow.1);
    let one = json!({"map_id": mid, "robots": [robots[0].clone()]});
    let response = server
        .client
        .post(format!("{}/v1/fleet-plans", server.base))
        .header("content-type", "application/json")
        .header("prefer", "wait=10, respond-async")
        .body(one.to_string())
        .send()
        .await
        .unwrap();
    assert_eq!(response.status(), StatusCode::ACCEPTED);
    assert_eq!(response.headers()["preference-applied"], "respond-async");
    let queued: Value = response.json().await.unwrap();
    let queued_id = queued["job_id"].as_str().unwrap();
    let (s, not_ready) = server.get(&format!("/v1/fleet-plans/{queued_id}")).await;
    problem(s, &not_ready, StatusCode::CONFLICT, "fleet_plan_not_ready");
    let (s, _) = server
        .send_as(None, "DELETE", &format!("/v1/jobs/{queued_id}"), None)
        .await;
    assert!(s.is_success(), "{s}");
    assert_eq!(server.wait_job(queued_id).await["state"], "cancelled");
    let (s, finished) = server.get(&format!("/v1/fleet-plans/{queued_id}")).await;
    problem(s, &finished, StatusCode::CONFLICT, "job_finished");
    let (s, missing) = server
        .get("/v1/fleet-plans/00000000000000000000000000000000")
        .await;
    problem(s, &missing, StatusCode::NOT_FOUND, "not_found");
    let (s, _) = server
        .send_as(
            None,
            "DELETE",
            &format!("/v1/jobs/{}", slow.1["job_id"].as_str().unwrap()),
            None,
        )
        .await;
    assert!(s.is_success(), "{s}");
}
