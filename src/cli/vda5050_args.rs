//! The CLI's VDA 5050 options and the `zones` command: the header both messages carry, the
//! order's own fields (`plan --output vda5050-order`) and the zone set (`irs-planner zones`).

use super::{Failure, MapArgs, build_map, load_scenario, print_json};
use clap::Args;
use irs_answers::vda5050::{self, Header, OrderParams, ZoneParams};
use irs_model::input::{FieldError, parse_finite};
use irs_model::radiomap::Unit;
use std::time::SystemTime;

/// The VDA 5050 header and map id of an order or a zone set.
#[derive(Debug, Args)]
pub struct HeaderArgs {
    /// headerId [default: 0].
    #[arg(long, value_name = "N")]
    pub header_id: Option<u32>,
    /// The robot's manufacturer [default: empty].
    #[arg(long, value_name = "NAME")]
    pub manufacturer: Option<String>,
    /// The robot's serialNumber [default: empty].
    #[arg(long, value_name = "NAME")]
    pub serial_number: Option<String>,
    /// The robot's id of the map (mapId; an order's default: --frame-id; a zone set's: map).
    #[arg(long, value_name = "ID")]
    pub vda_map_id: Option<String>,
}

impl HeaderArgs {
    fn given(&self) -> bool {
        self.header_id.is_some()
            || self.manufacturer.is_some()
            || self.serial_number.is_some()
            || self.vda_map_id.is_some()
    }

    fn header(&self) -> Header {
        Header {
            header_id: self.header_id.unwrap_or(0),
            manufacturer: self.manufacturer.clone().unwrap_or_default(),
            serial_number: self.serial_number.clone().unwrap_or_default(),
            map_id: self.vda_map_id.clone(),
        }
    }
}

/// The VDA 5050 order's fields that the path does not decide (`--output vda5050-order`).
#[derive(Debug, Args)]
#[command(next_help_heading = "VDA 5050 order (--output vda5050-order)")]
pub struct OrderArgs {
    #[command(flatten)]
    pub header: HeaderArgs,
    /// orderId (default: a hash of the map, the ends and the threshold).
    #[arg(long, value_name = "ID")]
    pub order_id: Option<String>,
    /// orderUpdateId [default: 0].
    #[arg(long, value_name = "N")]
    pub order_update_id: Option<u32>,
    /// How far above the threshold, in --unit, every cell from the last released node to the
    /// next must be [default: 0].
    #[arg(long, value_name = "VALUE", allow_hyphen_values = true, value_parser = parse_finite)]
    pub release_margin: Option<f64>,
}

impl OrderArgs {
    /// The order's parameters, or `None` when no option was given.
    pub(super) fn params(&self) -> Option<OrderParams> {
        let given = self.header.given()
            || self.order_id.is_some()
            || self.order_update_id.is_some()
            || self.release_margin.is_some();
        given.then(|| OrderParams {
            header: self.header.header(),
            order_id: self.order_id.clone(),
            order_update_id: self.order_update_id.unwrap_or(0),
            release_margin: self.release_margin.unwrap_or(0.0),
        })
    }
}

#[derive(Debug, Args)]
pub struct ZonesArgs {
    #[command(flatten)]
    pub map: MapArgs,
    /// QoS threshold γ in --unit (by default the map's: dB or bit/s/Hz): free cells below it
    /// are BLOCKED.
    #[arg(long, allow_hyphen_values = true, value_parser = parse_finite)]
    pub threshold: f64,
    /// The unit of the threshold and the band: gain_db, dbm, snr_db, bps_hz or mbps
    /// (docs/model.md §3.1); default: the map's own.
    #[arg(long, value_name = "UNIT")]
    pub unit: Option<Unit>,
    /// Width of the band above the threshold that gets PENALTY zones (in --unit); none
    /// without it.
    #[arg(long, value_name = "VALUE", value_parser = parse_finite)]
    pub penalty_band: Option<f64>,
    /// Steps of the penalty factor, 1–10 [default: 4].
    #[arg(long, value_name = "N")]
    pub penalty_levels: Option<usize>,
    /// zoneSetId (default: a hash of the map, the threshold, its unit and the penalties).
    #[arg(long, value_name = "ID")]
    pub zone_set_id: Option<String>,
    #[command(flatten)]
    pub header: HeaderArgs,
}

/// A field of a VDA 5050 message's parameters as its flag (`order.map_id` and `map_id` are
/// `--vda-map-id`).
pub(super) fn vda_flag(e: &FieldError) -> String {
    let field = e.field.strip_prefix("order.").unwrap_or(&e.field);
    let name = match field {
        "map_id" => "vda-map-id".to_string(),
        field => field.replace('_', "-"),
    };
    format!("--{name}: {}", e.reason)
}

/// `irs-planner zones …`: the zone set, as JSON.
pub fn run_zones(args: &ZonesArgs) -> Result<(), Failure> {
    let params = ZoneParams {
        header: args.header.header(),
        zone_set_id: args.zone_set_id.clone(),
        penalty_band: args.penalty_band,
        penalty_levels: args.penalty_levels,
    };
    params
        .validate()
        .map_err(|e| Failure::input(vda_flag(&e)))?;
    let scenario = load_scenario(&args.map.source)?;
    let map = build_map(&args.map, &scenario)?;
    let unit = args.unit.unwrap_or(map.native_unit());
    let zones = vda5050::zone_set(&map, unit, args.threshold, &params, SystemTime::now())
        .map_err(|e| Failure::input(vda_flag(&e)))?;
    print_json(&zones)
}
