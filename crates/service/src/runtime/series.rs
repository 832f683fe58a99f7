//! What every series on `/metrics` means: one HELP text per metric the service records,
//! registered in each server's registry when it is made, so an operator reading `/metrics` (or
//! a dashboard built from it) never has to guess. A test reads the service's source and fails
//! when a metric is recorded without being described here.

/// A metric's Prometheus type.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Kind {
    Counter,
    Gauge,
    Histogram,
}

use Kind::{Counter, Gauge, Histogram};

/// Every series the service records: name, type, HELP text (labels in brackets).
pub(crate) const SERIES: &[(&str, Kind, &str)] = &[
    (
        "http_requests_total",
        Counter,
        "HTTP answers [route template, method, status]",
    ),
    (
        "http_request_duration_seconds",
        Histogram,
        "Time to answer an HTTP request, body included [route template]",
    ),
    (
        "irs_request_timeouts_total",
        Counter,
        "Requests cut off at --request-timeout-s (503)",
    ),
    ("irs_connections_total", Counter, "TCP connections accepted"),
    (
        "irs_connections_refused_per_client_total",
        Counter,
        "Connections refused because the client already held --max-connections-per-client",
    ),
    (
        "irs_connections_idle_closed_total",
        Counter,
        "Keep-alive connections closed after their idle timeout",
    ),
    (
        "irs_connections_stalled_closed_total",
        Counter,
        "Connections closed because their answers made no progress (a client that stopped reading)",
    ),
    (
        "irs_auth_failures_total",
        Counter,
        "Requests refused with 401 (a bearer token this server does not accept, or none where one is needed)",
    ),
    (
        "irs_answers_in_flight_bytes",
        Gauge,
        "Bytes of built answers not yet delivered to slow clients (bounded by --answers-in-flight-mb)",
    ),
    (
        "irs_answers_refused_in_flight_total",
        Counter,
        "Answers refused with 503 because the in-flight budget was full",
    ),
    (
        "irs_answer_cache_requests_total",
        Counter,
        "Lookups of kept path answers [outcome: hit or miss]",
    ),
    (
        "irs_queries_waiting",
        Gauge,
        "Heavy queries waiting for a query worker",
    ),
    (
        "irs_queries_refused_total",
        Counter,
        "Heavy queries refused with 503 because the query queue was full [what]",
    ),
    (
        "irs_scenarios",
        Gauge,
        "Scenarios registered on this replica",
    ),
    (
        "irs_scenario_bytes",
        Gauge,
        "Bytes the registered scenarios hold (bounded by --registry-mb)",
    ),
    (
        "irs_scenarios_evicted_total",
        Counter,
        "API scenarios evicted by fair share to make room",
    ),
    (
        "irs_scenarios_refused_total",
        Counter,
        "Scenarios refused because the registry could not hold them [why]",
    ),
    (
        "irs_map_cache_entries",
        Gauge,
        "Maps in this replica's memory cache",
    ),
    (
        "irs_map_cache_bytes",
        Gauge,
        "Bytes of the maps in this replica's memory cache (bounded by --cache-mb)",
    ),
    (
        "irs_map_cache_requests_total",
        Counter,
        "Map lookups in this replica's cache and data directory [outcome: hit, disk or miss]",
    ),
    (
        "irs_map_builds_total",
        Counter,
        "Map builds started on this replica [kind: gain or rate]",
    ),
    ("irs_jobs", Gauge, "Jobs on this replica by state [state]"),
    (
        "irs_job_seconds",
        Histogram,
        "Run time of the jobs that ended [kind: map, placement, check or fleet]",
    ),
    (
        "irs_jobs_waiting",
        Gauge,
        "Jobs (map builds, placements, checks, fleet plans) waiting for a worker on this replica (bounded by --queue)",
    ),
    (
        "irs_jobs_running",
        Gauge,
        "Jobs running on this replica's workers (at most --workers)",
    ),
    (
        "irs_job_history_bytes",
        Gauge,
        "Bytes the finished jobs kept for their results hold (bounded by --job-history-mb)",
    ),
    (
        "irs_placements_total",
        Counter,
        "Placement searches started",
    ),
    (
        "irs_checks_total",
        Counter,
        "Monte Carlo path checks started as jobs",
    ),
    (
        "irs_fleet_plans_total",
        Counter,
        "Fleet plans started as jobs",
    ),
    (
        "irs_store_map_bytes",
        Gauge,
        "Bytes of the maps in the data directory (bounded by --data-maps-mb)",
    ),
    (
        "irs_store_write_errors_total",
        Counter,
        "Records the data directory failed to write [kind]",
    ),
    (
        "irs_store_corrupt_total",
        Counter,
        "Records in the data directory ignored as damaged [kind]",
    ),
    (
        "irs_data_dir_writable",
        Gauge,
        "1 while the data directory can be written, 0 while the replica is degraded by it",
    ),
    (
        "irs_redis_up",
        Gauge,
        "1 while Redis answers, 0 while the replica is degraded by it",
    ),
    (
        "irs_redis_repaired_total",
        Counter,
        "Redis keys holding what this build does not write, deleted or repaired where met [what]",
    ),
    (
        "irs_builds_claimed_total",
        Counter,
        "Builds this replica took over from a replica that stopped heartbeating",
    ),
    (
        "irs_maps_shared_late_total",
        Counter,
        "Maps built while Redis was away, stored in Redis once it answered",
    ),
    (
        "irs_map_rows_checkpointed_total",
        Counter,
        "Rate-map grid rows this replica's builds stored in their checkpoints in Redis",
    ),
    (
        "irs_map_rows_resumed_total",
        Counter,
        "Rate-map grid rows a build taken over here copied from its checkpoint instead of solving",
    ),
    (
        "irs_maps_not_shared_total",
        Counter,
        "Maps built here that Redis had no room for (at its maxmemory), kept here only [reason]",
    ),
    (
        "irs_redis_map_bytes",
        Gauge,
        "Bytes of the maps stored in Redis, as of this replica's last store (bounded by --redis-maps-mb)",
    ),
    (
        "irs_redis_maps_evicted_total",
        Counter,
        "Maps this replica evicted from Redis to store another within --redis-maps-mb",
    ),
];

/// Registers every series' HELP text in the current (the server's own) recorder, the
/// process's series (`process_*`, as Prometheus's own clients name them) included.
pub(crate) fn describe() {
    metrics_process::Collector::default().describe();
    for &(name, kind, help) in SERIES {
        match kind {
            Counter => metrics::describe_counter!(name, help),
            Gauge => metrics::describe_gauge!(name, help),
            Histogram => metrics::describe_histogram!(name, help),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::BTreeMap;

    /// Every `counter!`/`gauge!`/`histogram!` in the service's source names a series described
    /// above, with the same type; nothing described is no longer recorded.
    #[test]
    fn every_recorded_series_is_described() {
        let mut recorded = BTreeMap::new();
        let mut stack = vec![std::path::PathBuf::from(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/src"
        ))];
        while let Some(dir) = stack.pop() {
            for entry in std::fs::read_dir(&dir).unwrap() {
                let path = entry.unwrap().path();
                if path.is_dir() {
                    stack.push(path);
                    continue;
                }
                if path.extension().is_none_or(|e| e != "rs") || path.ends_with("series.rs") {
                    continue;
                }
                let text = std::fs::read_to_string(&path).unwrap();
                for (macro_name, kind) in [
                    ("counter!(", Counter),
                    ("gauge!(", Gauge),
                    ("histogram!(", Histogram),
                ] {
                    for (at, _) in text.match_indices(macro_name) {
                        let rest = text[at + macro_name.len()..].trim_start();
                        let Some(name) = rest.strip_prefix('"').and_then(|r| r.split('"').next())
                        else {
                            continue;
                        };
                        recorded.insert(name.to_string(), (kind, path.display().to_string()));
                    }
                }
            }
        }
        assert!(
            recorded.len() > 20,
            "the scan found the series: {recorded:?}"
        );
        let described: BTreeMap<_, _> =
            SERIES.iter().map(|&(n, k, _)| (n.to_string(), k)).collect();
        for (name, (kind, file)) in &recorded {
            assert_eq!(
                described.get(name),
                Some(kind),
                "{name} ({file}) is recorded but not described (or as another type)"
            );
        }
        for name in described.keys() {
            assert!(
                recorded.contains_key(name),
                "{name} is described but no longer recorded"
            );
        }
    }
}
