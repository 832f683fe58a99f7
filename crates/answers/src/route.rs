//! A planned path in the formats a robot stack reads: a ROS `nav_msgs/Path` message and a CSV
//! of poses, next to the JSON answer ([`RouteFormat`]; the VDA 5050 order is
//! [`crate::vda5050`]'s). Both carry what the answer's waypoints
//! carry of the route itself (position, heading, time, the map's value), in the answer's frame;
//! the IRS configuration stays in the JSON answer.

use irs_model::planner::PathAnswer;
use serde::{Deserialize, Serialize};
use serde_json::json;
use std::fmt::Write as _;

/// How a path answer is written.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum RouteFormat {
    /// The path answer (phases, powers, handovers; the API's JSON body).
    #[default]
    Json,
    /// A ROS 2 `nav_msgs/msg/Path` message as JSON: what `rosbridge` sends and, JSON being
    /// YAML, what `ros2 topic pub /plan nav_msgs/msg/Path "$(cat path.json)"` takes.
    NavMsgsPath,
    /// One line per waypoint: `x,y,yaw_rad,time_s,distance_m,value`, with a header line.
    Csv,
    /// A VDA 5050 order (see [`crate::vda5050`]).
    Vda5050Order,
}

impl std::str::FromStr for RouteFormat {
    type Err = String;

    fn from_str(text: &str) -> Result<Self, String> {
        match text {
            "json" => Ok(RouteFormat::Json),
            "nav_msgs_path" | "nav-msgs-path" => Ok(RouteFormat::NavMsgsPath),
            "csv" => Ok(RouteFormat::Csv),
            "vda5050_order" | "vda5050-order" => Ok(RouteFormat::Vda5050Order),
            other => Err(format!(
                "expected json, nav_msgs_path, csv or vda5050_order, got {other:?}"
            )),
        }
    }
}

/// A ROS time (`builtin_interfaces/Time`) `seconds` after the start: whole seconds and
/// nanoseconds, as the message splits them.
fn stamp(seconds: f64) -> serde_json::Value {
    let nanos = (seconds * 1e9).round().max(0.0) as u64;
    json!({"sec": nanos / 1_000_000_000, "nanosec": nanos % 1_000_000_000})
}

/// The path as a `nav_msgs/Path`: the path's header names the answer's frame at time 0; each
/// pose's header stamps the time the robot reaches it at V_max (seconds from the start, to add
/// to the moment the robot sets off), its orientation the heading as a quaternion about z.
/// An infeasible answer is an empty path.
pub fn nav_msgs_path<P>(path: &PathAnswer<P>) -> serde_json::Value {
    let poses: Vec<serde_json::Value> = path
        .waypoints
        .iter()
        .map(|w| {
            let half = w.yaw_rad / 2.0;
            json!({
                "header": {"stamp": stamp(w.time_s), "frame_id": path.frame_id},
                "pose": {
                    "position": {"x": w.x, "y": w.y, "z": 0.0},
                    "orientation": {"x": 0.0, "y": 0.0, "z": half.sin(), "w": half.cos()},
                },
            })
        })
        .collect();
    json!({
        "header": {"stamp": stamp(0.0), "frame_id": path.frame_id},
        "poses": poses,
    })
}

/// The path as CSV (RFC 4180, `\n` line ends): a header line, then per waypoint its position
/// (m), heading (rad), time and distance from the start (s, m) and the map's value there. An
/// infeasible answer is the header alone.
pub fn csv<P>(path: &PathAnswer<P>) -> String {
    let mut text = String::from("x,y,yaw_rad,time_s,distance_m,value\n");
    for w in &path.waypoints {
        // Shortest round-trip decimals, as the JSON answer writes them.
        let _ = writeln!(
            text,
            "{},{},{},{},{},{}",
            w.x, w.y, w.yaw_rad, w.time_s, w.distance_m, w.value
        );
    }
    text
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scenario::ScenarioDocument;
    use irs_model::phases::PhaseMode;
    use irs_model::planner::{self, Threshold};
    use irs_model::radiomap::{MapKey, Progress};
    use irs_model::scenario::Scenario;

    fn paper_path() -> PathAnswer {
        let floor = Scenario::builtin("paper-single-user").unwrap();
        let key = MapKey::gain(&floor.content_hash(), &floor, PhaseMode::Continuous).unwrap();
        let map = crate::map::build(&floor, &key, &Progress::default()).unwrap();
        planner::plan(
            &map,
            map.native_unit(),
            Default::default(),
            [-10.0, 0.0],
            [10.0, 0.0],
            Threshold::Max,
            0.5,
        )
        .unwrap()
    }

    /// The message's poses are the waypoints: positions, unit quaternions whose angle about z
    /// is the heading, stamps that grow with the time at V_max and split it as ROS does.
    #[test]
    fn nav_msgs_path_poses_are_the_waypoints() {
        let path = paper_path();
        let message = nav_msgs_path(&path);
        assert_eq!(message["header"]["frame_id"], "map");
        let poses = message["poses"].as_array().unwrap();
        assert_eq!(poses.len(), path.waypoints.len());
        for (pose, w) in poses.iter().zip(&path.waypoints) {
            assert_eq!(pose["pose"]["position"]["x"], w.x);
            assert_eq!(pose["pose"]["position"]["y"], w.y);
            let q = &pose["pose"]["orientation"];
            let (z, qw) = (q["z"].as_f64().unwrap(), q["w"].as_f64().unwrap());
            assert!((z.hypot(qw) - 1.0).abs() < 1e-12);
            assert!((2.0 * z.atan2(qw) - w.yaw_rad).abs() < 1e-12);
            let t = &pose["header"]["stamp"];
            let (sec, nanosec) = (t["sec"].as_u64().unwrap(), t["nanosec"].as_u64().unwrap());
            assert!(nanosec < 1_000_000_000);
            assert!((sec as f64 + nanosec as f64 * 1e-9 - w.time_s).abs() < 1e-9);
        }
    }

    /// One header and one line per waypoint, every number read back exactly.
    #[test]
    fn csv_lines_are_the_waypoints() {
        let path = paper_path();
        let text = csv(&path);
        let mut lines = text.lines();
        assert_eq!(lines.next(), Some("x,y,yaw_rad,time_s,distance_m,value"));
        let rows: Vec<Vec<f64>> = lines
            .map(|l| l.split(',').map(|v| v.parse().unwrap()).collect())
            .collect();
        assert_eq!(rows.len(), path.waypoints.len());
        for (row, w) in rows.iter().zip(&path.waypoints) {
            assert_eq!(row, &[w.x, w.y, w.yaw_rad, w.time_s, w.distance_m, w.value]);
        }
    }
}
