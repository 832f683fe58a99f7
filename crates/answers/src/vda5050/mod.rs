//! VDA 5050 (version 3.0.0, github.com/VDA5050/VDA5050): the messages a fleet's master sends
//! its AGVs, written from our answers — a planned path as an `order` ([`order`]) and the radio
//! map at a threshold as a `zoneSet` ([`zones`]). Both carry the same header ([`Header`]) and
//! are checked in CI against the official JSON schemas (`tests/data/vda5050/`).

pub mod order;
pub mod zones;

pub use order::{Order, OrderParams, order};
pub use zones::{ZoneParams, ZoneSet, zone_set};

use irs_model::input::FieldError;
use std::time::SystemTime;

/// The protocol version the messages are written in.
pub const VERSION: &str = "3.0.0";

/// Longest text accepted for an id or a name in a message (characters).
pub const MAX_TEXT_CHARS: usize = 200;

/// The header fields the master decides, and the robot's id of the map the positions are on.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Header {
    /// `headerId` (default 0).
    pub header_id: u32,
    /// `manufacturer` of the robot (default empty).
    pub manufacturer: String,
    /// `serialNumber` of the robot (default empty).
    pub serial_number: String,
    /// The map's id in the robot's terms (`mapId`); each message says what it defaults to.
    pub map_id: Option<String>,
}

impl Header {
    /// Checks the texts' lengths; errors name `<prefix>manufacturer` etc.
    pub fn validate(&self, prefix: &str) -> Result<(), FieldError> {
        check_text(&format!("{prefix}manufacturer"), Some(&self.manufacturer))?;
        check_text(&format!("{prefix}serial_number"), Some(&self.serial_number))?;
        check_text(&format!("{prefix}map_id"), self.map_id.as_deref())
    }
}

/// A text of at most [`MAX_TEXT_CHARS`] characters.
fn check_text(field: &str, text: Option<&str>) -> Result<(), FieldError> {
    match text {
        Some(t) if t.chars().count() > MAX_TEXT_CHARS => Err(FieldError::new(
            field,
            format!("longer than {MAX_TEXT_CHARS} characters"),
        )),
        _ => Ok(()),
    }
}

/// `now` as the specification writes a timestamp: `YYYY-MM-DDTHH:mm:ss.fffZ` (UTC).
fn timestamp(now: SystemTime) -> String {
    humantime::format_rfc3339_millis(now).to_string()
}
