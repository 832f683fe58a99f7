//! A planned path as a VDA 5050 `order` (`json_schemas/order.schema`): what a master sends an
//! AGV to drive it.
//!
//! * One node per vertex of the route (the start, every turn, the goal), with its position in
//!   the answer's frame and the order's `mapId`; one edge between consecutive nodes, with a
//!   straight degree-1 NURBS trajectory and its length. `sequenceId`s run 0, 1, 2, … through
//!   nodes and edges alternately, as §6.1.1 requires.
//! * **Where the released base ends.** A robot that loses its connection finishes its order up
//!   to the last released node (§4.1), so the base must end where the robot, stopped, is still
//!   in coverage. The base ends at the last node whose cells up to the next node all meet the
//!   threshold plus `release_margin` (the goal: its own cell), so a robot braking anywhere
//!   before the next node stops on such cells; everything after it is the horizon. The start is
//!   always released (§6.1.1), even when no node qualifies.
//! * No `maximumSpeed`: no radio rule forces a speed (the waypoints' times are at V_max), so
//!   none is invented. Node actions and edge actions are empty: the IRS phases are applied by
//!   the infrastructure, not by the robot, and stay in the JSON path answer.

use super::{Header, VERSION, check_text, timestamp};
use crate::scenario::hash_hex;
use irs_model::input::FieldError;
use irs_model::planner::PathAnswer;
use serde::Serialize;
use std::time::SystemTime;

/// What the master decides and the path does not: the header, the order's identity and the
/// margin the released base keeps.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct OrderParams {
    /// The header and the map's id (`nodePosition.mapId`; by default the answer's frame id).
    pub header: Header,
    /// `orderId`; by default a hash of the map, the ends and the threshold, so the same query
    /// names the same order.
    pub order_id: Option<String>,
    /// `orderUpdateId` (default 0: a new order).
    pub order_update_id: u32,
    /// How far above the threshold (in the path's unit) every cell from the last released node
    /// to the next must be (default 0).
    pub release_margin: f64,
}

impl OrderParams {
    /// Checks the parameters (errors name `order.<field>`).
    pub fn validate(&self) -> Result<(), FieldError> {
        self.header.validate("order.")?;
        check_text("order.order_id", self.order_id.as_deref())?;
        if !self.release_margin.is_finite() || self.release_margin < 0.0 {
            return Err(FieldError::new(
                "order.release_margin",
                "must be a finite number ≥ 0 (in the path's unit)",
            ));
        }
        Ok(())
    }
}

/// A VDA 5050 `order` message.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(rename_all = "camelCase")]
pub struct Order {
    header_id: u32,
    timestamp: String,
    version: &'static str,
    manufacturer: String,
    serial_number: String,
    order_id: String,
    order_update_id: u32,
    order_description: String,
    nodes: Vec<Node>,
    edges: Vec<Edge>,
}

#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(rename_all = "camelCase")]
struct Node {
    node_id: String,
    sequence_id: u32,
    released: bool,
    node_position: NodePosition,
    actions: [(); 0],
}

#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(rename_all = "camelCase")]
struct NodePosition {
    x: f64,
    y: f64,
    map_id: String,
}

#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(rename_all = "camelCase")]
struct Edge {
    edge_id: String,
    sequence_id: u32,
    released: bool,
    trajectory: Trajectory,
    length: f64,
    actions: [(); 0],
}

/// A straight segment as a clamped degree-1 NURBS: its two ends, knots [0, 0, 1, 1].
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(rename_all = "camelCase")]
struct Trajectory {
    degree: u32,
    knot_vector: [f64; 4],
    control_points: [ControlPoint; 2],
}

#[derive(Debug, Clone, PartialEq, Serialize)]
struct ControlPoint {
    x: f64,
    y: f64,
}

/// The index of the last node of the released base (see the module's notes): the last vertex
/// whose cells up to the next vertex (the goal: its own cell) all meet `floor`; 0 when none
/// does.
fn last_released(values: &[f64], vertices: &[usize], floor: f64) -> usize {
    let meets = |from: usize, to: usize| values[from..=to].iter().all(|v| *v >= floor);
    (0..vertices.len())
        .rev()
        .find(|&k| match vertices.get(k + 1) {
            Some(&next) => meets(vertices[k], next),
            None => meets(vertices[k], vertices[k]),
        })
        .unwrap_or(0)
}

/// The path as an order sent at `now`. An infeasible answer has no route to order: the error
/// names `threshold`.
pub fn order<P>(
    path: &PathAnswer<P>,
    params: &OrderParams,
    now: SystemTime,
) -> Result<Order, FieldError> {
    params.validate()?;
    let threshold = match (path.feasible, path.threshold) {
        (true, Some(threshold)) if !path.vertices.is_empty() => threshold,
        _ => {
            return Err(FieldError::new(
                "threshold",
                "no path meets the threshold, so there is no route to order",
            ));
        }
    };
    let values: Vec<f64> = path.waypoints.iter().map(|w| w.value).collect();
    let base_end = last_released(&values, &path.vertices, threshold + params.release_margin);
    let map_id = params
        .header
        .map_id
        .clone()
        .unwrap_or_else(|| path.frame_id.clone());
    let nodes: Vec<Node> = path
        .vertices
        .iter()
        .enumerate()
        .map(|(k, &w)| Node {
            node_id: format!("n{k}"),
            sequence_id: 2 * k as u32,
            released: k <= base_end,
            node_position: NodePosition {
                x: path.waypoints[w].x,
                y: path.waypoints[w].y,
                map_id: map_id.clone(),
            },
            actions: [],
        })
        .collect();
    let edges = path
        .vertices
        .windows(2)
        .enumerate()
        .map(|(k, pair)| {
            let (a, b) = (&path.waypoints[pair[0]], &path.waypoints[pair[1]]);
            Edge {
                edge_id: format!("e{k}"),
                sequence_id: 2 * k as u32 + 1,
                released: k < base_end,
                trajectory: Trajectory {
                    degree: 1,
                    knot_vector: [0.0, 0.0, 1.0, 1.0],
                    control_points: [
                        ControlPoint { x: a.x, y: a.y },
                        ControlPoint { x: b.x, y: b.y },
                    ],
                },
                length: (b.x - a.x).hypot(b.y - a.y),
                actions: [],
            }
        })
        .collect();
    let order_id = params.order_id.clone().unwrap_or_else(|| {
        let (s, g) = (&path.start, &path.goal);
        hash_hex(
            format!(
                "{} {},{} {},{} {threshold} {}",
                path.map_id,
                s.x,
                s.y,
                g.x,
                g.y,
                path.unit.name()
            )
            .as_bytes(),
        )
    });
    Ok(Order {
        header_id: params.header.header_id,
        timestamp: timestamp(now),
        version: VERSION,
        manufacturer: params.header.manufacturer.clone(),
        serial_number: params.header.serial_number.clone(),
        order_id,
        order_update_id: params.order_update_id,
        order_description: format!(
            "irs-planner: map {}, threshold {threshold} {unit}, release margin {} {unit}",
            path.map_id,
            params.release_margin,
            unit = path.unit.symbol()
        ),
        nodes,
        edges,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The base ends at the last vertex whose cells to the next all meet the floor, whatever
    /// lies between; the start is released even when nothing qualifies.
    #[test]
    fn the_base_ends_at_the_last_vertex_whose_next_leg_meets_the_floor() {
        // Vertices at waypoints 0, 2, 5 and 7 (the goal): legs 0..=2, 2..=5, 5..=7, and 7.
        let vertices = [0, 2, 5, 7];
        let with = |weak: &[usize]| {
            let mut values = [5.0; 8];
            for &k in weak {
                values[k] = 1.0;
            }
            last_released(&values, &vertices, 4.0)
        };
        assert_eq!(with(&[]), 3, "every leg meets the floor: all released");
        assert_eq!(
            with(&[3]),
            3,
            "a weak cell the robot drives past does not stop the base"
        );
        assert_eq!(
            with(&[7]),
            1,
            "a weak goal: v2's leg ends on it, v1's is whole"
        );
        assert_eq!(with(&[3, 7]), 0, "then v1's leg is weak too");
        assert_eq!(with(&[0, 3, 7]), 0, "nothing qualifies: the start alone");
        assert_eq!(
            with(&[5]),
            3,
            "a weak vertex v2 does not stop a strong goal"
        );
        assert_eq!(last_released(&[3.0], &[0], 2.0), 0);
    }
}
