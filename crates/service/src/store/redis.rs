//! The shared store of replicas (`serve --redis-url URL`): Redis, through which any replica
//! answers for any scenario, map or job, and a map is built once in the whole cluster. This is
//! storage and coordination only; the build loop that reads the stream is the application's
//! (`app::builder`).
//!
//! What lives in Redis (keys under `irs:`):
//! * `irs:scenario:<id>`: a registered API scenario (its canonical document and owner digests,
//!   the record `--data-dir` writes too);
//! * `irs:map:<id>`: a built map in its compact binary form (`radiomap::encoding`), framed with
//!   its SHA-256 like a data-directory file; each replica keeps its moka cache in front;
//! * `irs:map-sizes` (hash: map id → bytes) and `irs:map-lru` (sorted set: map id → the time of
//!   its last store or read from Redis, in µs): the maps' budget (`--redis-maps-mb`). Storing a
//!   map first evicts the least recently used ones until it fits ([`STORE_MAP`]), so Redis runs
//!   on `noeviction` and never loses a lock, a stream entry or a job record to its own eviction.
//!   An evicted map is built again by the next request for it (`POST /v1/maps`), as one the
//!   replicas' caches let go of; reads are the replicas' cache misses, so "recently used" is
//!   recent in Redis, not in the replicas' caches;
//! * `irs:job:<id>`: a map job's record (state, progress, times, error), rewritten by the
//!   replica building it once per heartbeat; `irs:cancel:<id>` asks that replica to cancel;
//! * `irs:map-owners:<map id>`: with tokens on, the set of owner digests that asked for the map
//!   (a tenant without a claim is told the map does not exist); a claim is withdrawn with a
//!   script that deletes the map with the last claim;
//! * `irs:job-owners:<job id>`: the set of owner digests that share a build; a cancel withdraws
//!   one with a script that asks the builder to stop only when the last one withdraws;
//! * `irs:scenario-maps:<scenario id>`: the ids of the maps stored from that scenario, deleted
//!   with it (atomically, in a script);
//! * the channel `irs:deleted`: `scenario <id>` or `map <id>`, published by the replica that
//!   deleted it, so every replica drops its copy (`app::deletions`);
//! * `irs:building:<map id>`: the single-flight lock, the id of the job building the map, set
//!   with NX and an expiry that the builder renews every heartbeat;
//! * `irs:checkpoint:<map id>`: a rate-map build's progress, a list of batches of solved grid
//!   rows (`encoding::encode_rows`) its builder appends every [`crate::app::builder`] checkpoint
//!   period and once more when a graceful stop interrupts it; the replica that takes the build
//!   over copies those rows instead of solving them again. The key goes once the built map is
//!   shared, before the job reports done, or when a build ends otherwise (at the latest
//!   [`CHECKPOINT_TTL_S`] after its last append). Outside the maps' budget: at most one map's
//!   worth per running build;
//! * the stream `irs:builds` with the consumer group `builders`: one entry per build. Every
//!   replica reads it (`XREADGROUP`) when it has a free worker; an entry stays pending until
//!   its build ends (`XACK`, then `XDEL`). The builder's heartbeat re-claims its own entry to
//!   reset its idle time, so an entry idle for [`CLAIM_IDLE`] belongs to a dead replica and
//!   the next replica with a free worker takes it over (`XAUTOCLAIM`) and builds the map.
//!
//! Content that is not what this build writes (a record that does not parse, a map whose
//! digest fails, a key of the wrong Redis type, a lock without an expiry) is repaired where it
//! is met: the key is deleted (or its expiry set), logged and counted in
//! `irs_redis_repaired_total{what}`, and treated as missing, so the next request rebuilds or
//! re-registers it instead of failing on it forever.
//!
//! Redis down: a background task pings it every [`HEALTH_PERIOD`]; while it fails, `/readyz`
//! answers 503 with the reason, a request that needs Redis answers 503 with `Retry-After`,
//! maps already in a replica's cache still answer path queries, and everything resumes when
//! the ping succeeds again (the client reconnects by itself).
//!
//! The records are the application's (its scenario and job records); the store keeps them
//! as JSON text and reads them back as the type it is asked for, so it depends on no type
//! above it.

use super::disk as store;
use super::{Entry, Error, Store};
use crate::ids::{JobId, MapId, ScenarioId};
use irs_model::radiomap::MapKey;
use redis::aio::{ConnectionManager, ConnectionManagerConfig};
use redis::streams::{
    StreamAutoClaimOptions, StreamAutoClaimReply, StreamClaimOptions, StreamId, StreamReadOptions,
    StreamReadReply,
};
use redis::{AsyncCommands, ExistenceCheck, SetExpiry, SetOptions};
use serde::Serialize;
use std::sync::{Mutex, RwLock};
use std::time::{Duration, Instant};

pub(crate) const STREAM: &str = "irs:builds";
const GROUP: &str = "builders";
/// How often a builder renews its lock, re-claims its stream entry and publishes progress:
/// progress seen from other replicas is at most this old.
pub(crate) const HEARTBEAT: Duration = Duration::from_millis(500);
/// The lock's expiry: ten heartbeats, so a slow Redis round trip never loses a live lock, and
/// a dead builder's lock is gone within seconds.
const LEASE: Duration = Duration::from_secs(5);
/// A stream entry idle this long (no heartbeat re-claimed it) is a dead replica's build.
pub(crate) const CLAIM_IDLE: Duration = Duration::from_secs(5);
/// How long one `XREADGROUP` waits for an entry; also the longest a replica takes to notice
/// that it should stop reading.
const READ_BLOCK: Duration = Duration::from_millis(1000);
pub(crate) const HEALTH_PERIOD: Duration = Duration::from_millis(500);
/// Connection and response timeouts: a Redis that does not answer within them counts as down
/// (the response timeout is above `READ_BLOCK`, which a blocking read legitimately waits).
const CONNECT_TIMEOUT: Duration = Duration::from_secs(1);
const RESPONSE_TIMEOUT: Duration = Duration::from_secs(3);
/// Cancellation requests and job records outlive any job: a day.
const RECORD_TTL_S: u64 = 86_400;

fn scenario_key(id: &ScenarioId) -> String {
    format!("irs:scenario:{id}")
}
fn map_key(id: &MapId) -> String {
    format!("{MAP_PREFIX}{id}")
}
fn job_key(id: &JobId) -> String {
    format!("irs:job:{id}")
}
fn cancel_key(id: &JobId) -> String {
    format!("irs:cancel:{id}")
}
fn lock_key(map_id: &MapId) -> String {
    format!("irs:building:{map_id}")
}
fn map_owners_key(id: &MapId) -> String {
    format!("irs:map-owners:{id}")
}
fn job_owners_key(id: &JobId) -> String {
    format!("irs:job-owners:{id}")
}
fn scenario_maps_key(id: &ScenarioId) -> String {
    format!("irs:scenario-maps:{id}")
}
fn checkpoint_key(map_id: &MapId) -> String {
    format!("irs:checkpoint:{map_id}")
}
/// How long a build's checkpoint outlives its last append: a build no replica takes over
/// within it starts again from zero. Checkpoints lie outside the maps' budget; this bounds
/// what an abandoned one holds.
const CHECKPOINT_TTL_S: i64 = 3_600;
const MAP_PREFIX: &str = "irs:map:";
const MAP_SIZES: &str = "irs:map-sizes";
const MAP_LRU: &str = "irs:map-lru";

/// Stores a map within the maps' budget, atomically. KEYS: the map's key, its scenario's set
/// of maps, [`MAP_LRU`], [`MAP_SIZES`]; ARGV: the map id, its framed bytes, the budget in
/// bytes, [`MAP_PREFIX`]. The total is summed afresh from the sizes of the maps that still
/// exist (a map deleted with its scenario, its last claim or a repair leaves its size behind,
/// dropped here), so no counter can drift; a size without a place in the order counts as the
/// oldest. Then the least recently used maps are deleted until the new one fits; a map larger
/// than the whole budget is stored alone (requests for such maps are refused beforehand, see
/// `app::maps`). Returns {maps evicted, bytes stored now}. Standalone Redis only (keys built
/// in the script). The `#!lua` line (Redis 7) makes Redis refuse the whole script while it is
/// past its `maxmemory`: a script without it is refused only at its first write, and its
/// first writes here delete, after which Redis lets every later write of the script through.
const STORE_MAP: &str = r"#!lua
local id, size, budget, prefix = ARGV[1], string.len(ARGV[2]), tonumber(ARGV[3]), ARGV[4]
redis.call('HDEL', KEYS[4], id)
redis.call('ZREM', KEYS[3], id)
local total, evicted = 0, 0
local sizes = redis.call('HGETALL', KEYS[4])
for i = 1, #sizes, 2 do
  if redis.call('EXISTS', prefix .. sizes[i]) == 1 then
    total = total + tonumber(sizes[i + 1])
    redis.call('ZADD', KEYS[3], 'NX', 0, sizes[i])
  else
    redis.call('HDEL', KEYS[4], sizes[i])
    redis.call('ZREM', KEYS[3], sizes[i])
  end
end
while total + size > budget do
  local oldest = redis.call('ZRANGE', KEYS[3], 0, 0)[1]
  if not oldest then break end
  total = total - tonumber(redis.call('HGET', KEYS[4], oldest) or '0')
  redis.call('DEL', prefix .. oldest)
  redis.call('ZREM', KEYS[3], oldest)
  redis.call('HDEL', KEYS[4], oldest)
  evicted = evicted + 1
end
local now = redis.call('TIME')
redis.call('SET', KEYS[1], ARGV[2])
redis.call('SADD', KEYS[2], id)
redis.call('HSET', KEYS[4], id, size)
redis.call('ZADD', KEYS[3], now[1] * 1000000 + now[2], id)
return {evicted, total + size}
";

/// Marks a map (ARGV[1]) used now in [`MAP_LRU`] (KEYS[1]), if it is still there.
const TOUCH_MAP: &str = r"
local now = redis.call('TIME')
return redis.call('ZADD', KEYS[1], 'XX', now[1] * 1000000 + now[2], ARGV[1])
";

/// The channel on which a replica that deletes a scenario or a map tells the others, which
/// drop their copies (`app::deletions`): `scenario <id>` or `map <id>`.
const DELETIONS: &str = "irs:deleted";

/// Something deleted on one replica, which every other must forget.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) enum Deleted {
    Scenario(ScenarioId),
    Map(MapId),
}

impl Deleted {
    fn message(&self) -> String {
        match self {
            Deleted::Scenario(id) => format!("scenario {id}"),
            Deleted::Map(id) => format!("map {id}"),
        }
    }

    fn parse(message: &str) -> Option<Deleted> {
        match message.split_once(' ')? {
            ("scenario", id) => Some(Deleted::Scenario(ScenarioId::given(id))),
            ("map", id) => Some(Deleted::Map(MapId::given(id))),
            _ => None,
        }
    }
}

/// Deletes a scenario's record (KEYS[1]) with every map built from it: the set KEYS[2] names
/// them, and ARGV[1], ARGV[2] prefix a map's key and its claims' key. Atomic, so a map stored
/// meanwhile is either deleted or stored after (and then deleted with the scenario's next
/// deletion). Returns 1 if the record was there. Standalone Redis only (keys built in the script).
const DELETE_SCENARIO: &str = r"
for _, m in ipairs(redis.call('SMEMBERS', KEYS[2])) do
  redis.call('DEL', ARGV[1] .. m, ARGV[2] .. m)
end
redis.call('DEL', KEYS[2])
return redis.call('DEL', KEYS[1])
";

/// Withdraws one owner (ARGV[1]) from the set KEYS[1], atomically with what follows when it
/// is the last: with ARGV[2] = "del" KEYS[2] is deleted with the set (a map nobody claims any
/// more); otherwise KEYS[2] is set for ARGV[3] seconds and the last owner stays in the set (a
/// build nobody wants is asked to stop, and stays its last owner's to read). Returns the
/// owners left, or -1 if ARGV[1] was not one (then nothing changes).
const WITHDRAW: &str = r"
if redis.call('SISMEMBER', KEYS[1], ARGV[1]) == 0 then return -1 end
local left = redis.call('SCARD', KEYS[1]) - 1
if left > 0 then
  redis.call('SREM', KEYS[1], ARGV[1])
elseif ARGV[2] == 'del' then
  redis.call('DEL', KEYS[1], KEYS[2])
else
  redis.call('SET', KEYS[2], '1', 'EX', tonumber(ARGV[3]))
end
return left
";
/// One build, as the stream carries it.
#[derive(Debug, Clone)]
pub(crate) struct BuildEntry {
    pub stream_id: String,
    pub job_id: JobId,
    pub map_id: MapId,
    pub key: MapKey,
}

impl BuildEntry {
    fn of(entry: &StreamId) -> Option<BuildEntry> {
        let job_id: String = entry.get("job_id")?;
        let map_id: String = entry.get("map_id")?;
        let key: String = entry.get("key")?;
        let key: MapKey = serde_json::from_str(&key).ok()?;
        (MapId::of(&key).as_str() == map_id).then(|| BuildEntry {
            stream_id: entry.id.clone(),
            job_id: JobId::given(job_id),
            map_id: MapId::given(map_id),
            key,
        })
    }
}

/// The connection to Redis and what the replica knows of its health.
pub(crate) struct Cluster {
    client: redis::Client,
    /// This replica's consumer name in the group: unique per process.
    pub replica: String,
    /// Commands share one multiplexed connection (it reconnects by itself); `None` until the
    /// first connection succeeds.
    commands: RwLock<Option<ConnectionManager>>,
    /// `None` while Redis answers; the reason while it does not.
    down: Mutex<Option<String>>,
    /// When Redis last became available to this replica (see [`Cluster::next_build`]).
    up_since: Mutex<Option<Instant>>,
    /// Whether this replica follows the deletions channel now. Until it does it could serve
    /// what another replica deleted, so the store counts as unavailable (at start-up, and
    /// after Redis was away, until the subscription is made again).
    following: std::sync::atomic::AtomicBool,
    /// The bytes the maps stored in Redis may take together (`--redis-maps-mb`).
    maps_budget: u64,
}

fn config() -> ConnectionManagerConfig {
    ConnectionManagerConfig::new()
        .set_connection_timeout(Some(CONNECT_TIMEOUT))
        .set_response_timeout(Some(RESPONSE_TIMEOUT))
        .set_number_of_retries(1)
}

impl Cluster {
    /// Checks the URL (no connection yet: a replica starts even while Redis is down); the maps
    /// it stores in Redis take at most `maps_budget` bytes together.
    pub fn new(url: &str, maps_budget: u64) -> Result<Cluster, String> {
        let client = redis::Client::open(url).map_err(|e| format!("--redis-url: {e}"))?;
        let replica = format!(
            "{}-{}",
            std::process::id(),
            &uuid::Uuid::new_v4().simple().to_string()[..8]
        );
        Ok(Cluster {
            client,
            replica,
            commands: RwLock::new(None),
            down: Mutex::new(Some("not connected to Redis yet".into())),
            up_since: Mutex::new(None),
            following: std::sync::atomic::AtomicBool::new(false),
            maps_budget,
        })
    }

    /// A dedicated connection (the builder's blocking reads must not hold up the commands).
    pub async fn connect(&self) -> redis::RedisResult<ConnectionManager> {
        self.client
            .get_connection_manager_with_config(config())
            .await
    }

    fn mark(&self, down: Option<String>) {
        let mut state = self.down.lock().expect("cluster lock");
        if state.is_some() != down.is_some() {
            match &down {
                Some(reason) => tracing::warn!(reason = %reason, "Redis unavailable"),
                None => tracing::info!("Redis available"),
            }
            metrics::gauge!("irs_redis_up").set(if down.is_none() { 1.0 } else { 0.0 });
            *self.up_since.lock().expect("cluster lock") = down.is_none().then(Instant::now);
            if down.is_some() {
                // The subscription's connection went with the others (or may have).
                self.stopped_following();
            }
        }
        *state = down;
    }

    /// A command's failure: this request's 503. A lost or refused connection also marks Redis
    /// down for every request at once; a reply slower than `RESPONSE_TIMEOUT` does not, because
    /// on a loaded machine one slow reply is not an outage, and marking the store down for it
    /// failed every replica's readiness together (all three left HAProxy's pool in a CI run).
    /// A Redis that stops answering fails the health loop's ping within `RESPONSE_TIMEOUT` +
    /// `HEALTH_PERIOD`, which marks it down then.
    fn error(&self, e: &redis::RedisError) -> Error {
        let reason = format!("Redis: {e}");
        if e.code() == Some("OOM") {
            // Waiting does not make room: an operator must (see `--redis-maps-mb`).
            return Error::NoRoom { reason };
        }
        if e.is_io_error() && !e.is_timeout()
            || e.is_connection_dropped()
            || e.is_connection_refusal()
        {
            self.mark(Some(reason.clone()));
        }
        Error::unavailable(reason)
    }

    /// Deletes `key`, which held what this build does not write there (`what` names it in the
    /// counter), so that it is rebuilt or registered again rather than failing forever.
    async fn discard_key(
        &self,
        conn: &mut ConnectionManager,
        key: &str,
        what: &'static str,
        why: &str,
    ) {
        let removed: redis::RedisResult<usize> = conn.del(key).await;
        tracing::warn!(
            key,
            what,
            why,
            deleted = removed.is_ok(),
            "Redis key repaired"
        );
        metrics::counter!("irs_redis_repaired_total", "what" => what).increment(1);
    }

    /// `GET key`: a key of another Redis type (`WRONGTYPE`) is deleted and read as missing.
    async fn get_or_repair<T: redis::FromRedisValue>(
        &self,
        conn: &mut ConnectionManager,
        key: &str,
        what: &'static str,
    ) -> Result<Option<T>, Error> {
        match conn.get::<_, Option<T>>(key).await {
            Ok(value) => Ok(value),
            Err(e) if e.code() == Some("WRONGTYPE") => {
                self.discard_key(conn, key, what, "wrong Redis type").await;
                Ok(None)
            }
            Err(e) => Err(self.error(&e)),
        }
    }

    /// The command connection, or 503 while Redis is down.
    fn conn(&self) -> Result<ConnectionManager, Error> {
        if let Some(reason) = self.unavailable() {
            return Err(Error::unavailable(reason));
        }
        self.commands
            .read()
            .expect("cluster lock")
            .clone()
            .ok_or_else(|| Error::unavailable("not connected to Redis yet"))
    }

    /// Pings Redis forever: connects the first time, creates the consumer group, and keeps
    /// the health flag that `/readyz` and [`Cluster::conn`] read.
    pub async fn watch_health(&self) {
        loop {
            let existing = self.commands.read().expect("cluster lock").clone();
            let conn = match existing {
                Some(conn) => Ok(conn),
                None => match self.connect().await {
                    Ok(mut conn) => {
                        if let Some(reason) = self.check_settings(&mut conn).await {
                            // Nothing this build writes would work there: degraded, with why.
                            self.mark(Some(reason));
                            tokio::time::sleep(HEALTH_PERIOD * 10).await;
                            continue;
                        }
                        self.adopt_unbudgeted_maps(&mut conn).await;
                        *self.commands.write().expect("cluster lock") = Some(conn.clone());
                        Ok(conn)
                    }
                    Err(e) => Err(e),
                },
            };
            let outcome = match conn {
                Ok(mut conn) => match redis::cmd("PING").query_async::<String>(&mut conn).await {
                    Ok(_) => self.ensure_group(&mut conn).await,
                    Err(e) => Err(e),
                },
                Err(e) => Err(e),
            };
            self.mark(outcome.err().map(|e| format!("Redis: {e}")));
            tokio::time::sleep(HEALTH_PERIOD).await;
        }
    }

    /// What this build needs of Redis, read once per connection: version 7 or later (the
    /// map-storing script is a Redis 7 script), the reason it cannot be used otherwise. Warns
    /// when the memory settings break what the maps' budget relies on: an eviction policy
    /// other than `noeviction` may evict locks, build entries and job records, and a
    /// `maxmemory` not above the budget fills Redis before the budget evicts (then stores fail
    /// with 507 `store_full`). `INFO` may be renamed away, which only skips the checks.
    async fn check_settings(&self, conn: &mut ConnectionManager) -> Option<String> {
        let info = redis::cmd("INFO").query_async::<String>(conn).await.ok()?;
        let field = |name: &str| {
            info.lines()
                .find_map(|line| line.strip_prefix(name)?.strip_prefix(':'))
                .map(str::trim)
        };
        if let Some(policy) = field("maxmemory_policy")
            && policy != "noeviction"
        {
            tracing::warn!(
                policy,
                "Redis evicts keys on its own (maxmemory-policy): locks, build entries and job records may go with them; set it to noeviction, the maps have their own budget (--redis-maps-mb)"
            );
        }
        let maxmemory = field("maxmemory").and_then(|v| v.parse::<u64>().ok());
        if let Some(max) = maxmemory
            && max > 0
            && max <= self.maps_budget
        {
            tracing::warn!(
                maxmemory = max,
                maps_budget = self.maps_budget,
                "Redis's maxmemory is not above the maps' budget (--redis-maps-mb): Redis fills before the budget evicts a map"
            );
        }
        let version = field("redis_version")?;
        let major: u32 = version.split('.').next()?.parse().ok()?;
        (major < 7)
            .then(|| format!("Redis {version} is too old: irs-planner needs Redis 7 or later"))
    }

    /// Brings maps stored outside the budget (by a build before it, or by a replica of one
    /// during a rolling update) into it, as the least recently used, so storing the next map
    /// can evict them. Once per connection; a pass over the map keys (`SCAN`, so Redis serves
    /// other commands meanwhile). Best effort.
    async fn adopt_unbudgeted_maps(&self, conn: &mut ConnectionManager) {
        let keys: Vec<redis::RedisResult<String>> =
            match conn.scan_match::<_, String>(format!("{MAP_PREFIX}*")).await {
                Ok(iter) => futures_util::StreamExt::collect(iter).await,
                Err(_) => return,
            };
        let keys: Vec<String> = keys.into_iter().filter_map(Result::ok).collect();
        let mut adopted = 0usize;
        for key in keys {
            let Some(id) = key.strip_prefix(MAP_PREFIX) else {
                continue;
            };
            let known: redis::RedisResult<bool> = conn.hexists(MAP_SIZES, id).await;
            if !matches!(known, Ok(false)) {
                continue;
            }
            let Ok(bytes) = conn.strlen::<_, u64>(&key).await else {
                continue;
            };
            let added: redis::RedisResult<()> = redis::pipe()
                .atomic()
                .hset_nx(MAP_SIZES, id, bytes)
                .ignore()
                .zadd(MAP_LRU, id, 0)
                .ignore()
                .query_async(conn)
                .await;
            adopted += usize::from(added.is_ok());
        }
        if adopted > 0 {
            tracing::info!(adopted, "maps stored outside the budget brought into it");
        }
    }

    /// The consumer group, created with the stream if missing (idempotent). A key of another
    /// type where the stream belongs holds no build: it is deleted and the stream created.
    async fn ensure_group(&self, conn: &mut ConnectionManager) -> redis::RedisResult<()> {
        let created: redis::RedisResult<()> = conn.xgroup_create_mkstream(STREAM, GROUP, "0").await;
        match created {
            Err(e) if e.code() == Some("BUSYGROUP") => Ok(()),
            Err(e) if e.code() == Some("WRONGTYPE") => {
                self.discard_key(conn, STREAM, "stream", "wrong Redis type")
                    .await;
                let created: redis::RedisResult<()> =
                    conn.xgroup_create_mkstream(STREAM, GROUP, "0").await;
                match created {
                    Err(e) if e.code() == Some("BUSYGROUP") => Ok(()),
                    other => other,
                }
            }
            other => other,
        }
    }

    /// Stores a map's encoded bytes, framed with their digest, listed under the scenario it
    /// was built from (deleted with it), within the maps' budget: the least recently used maps
    /// are evicted to make room ([`STORE_MAP`]).
    pub async fn put_map(
        &self,
        id: &MapId,
        scenario: &ScenarioId,
        encoded: &[u8],
    ) -> Result<(), Error> {
        let mut conn = self.conn()?;
        let script = redis::Script::new(STORE_MAP);
        let mut invocation = script.prepare_invoke();
        invocation
            .key(map_key(id))
            .key(scenario_maps_key(scenario))
            .key(MAP_LRU)
            .key(MAP_SIZES)
            .arg(id.as_str())
            .arg(store::frame(encoded))
            .arg(self.maps_budget)
            .arg(MAP_PREFIX);
        let mut stored = invocation.invoke_async::<(u64, u64)>(&mut conn).await;
        if matches!(&stored, Err(e) if e.code() == Some("WRONGTYPE")) {
            // A key of the budget's (or the scenario's list) that is not what this build writes:
            // deleted, and the map stored again.
            for (key, kind) in [
                (MAP_LRU.to_string(), "zset"),
                (MAP_SIZES.to_string(), "hash"),
                (scenario_maps_key(scenario), "set"),
            ] {
                let found: redis::RedisResult<String> =
                    redis::cmd("TYPE").arg(&key).query_async(&mut conn).await;
                if matches!(&found, Ok(t) if t != kind && t != "none") {
                    self.discard_key(&mut conn, &key, "map budget", "wrong Redis type")
                        .await;
                }
            }
            stored = invocation.invoke_async(&mut conn).await;
        }
        let (evicted, bytes) = stored.map_err(|e| self.error(&e))?;
        metrics::gauge!("irs_redis_map_bytes").set(bytes as f64);
        if evicted > 0 {
            metrics::counter!("irs_redis_maps_evicted_total").increment(evicted);
            tracing::info!(map_id = %id, evicted, bytes, budget = self.maps_budget, "maps evicted from Redis to make room");
        }
        Ok(())
    }

    /// Tells every replica (this one included) that something was deleted. Best effort: a
    /// replica that misses it (not connected to Redis at the time) keeps its copy until its
    /// cache lets go of it.
    async fn announce(&self, conn: &mut ConnectionManager, deleted: Deleted) {
        let sent: redis::RedisResult<usize> = conn.publish(DELETIONS, deleted.message()).await;
        if let Err(e) = sent {
            tracing::warn!(deleted = ?deleted, error = %e, "a deletion not announced to the other replicas");
        }
    }

    /// The subscription of [`Cluster::deletions`] ended: unavailable until the next one.
    pub fn stopped_following(&self) {
        self.following
            .store(false, std::sync::atomic::Ordering::SeqCst);
    }

    /// When Redis last became available to this replica (`None` while it is not): a change
    /// means the connections of before may be gone, subscriptions included.
    pub fn up_since(&self) -> Option<Instant> {
        *self.up_since.lock().expect("cluster lock")
    }

    /// The deletions announced by any replica, from now on; the stream ends when the
    /// subscription's connection does (subscribe again).
    pub async fn deletions(
        &self,
    ) -> redis::RedisResult<impl futures_util::Stream<Item = Deleted> + use<>> {
        let mut pubsub = self.client.get_async_pubsub().await?;
        pubsub.subscribe(DELETIONS).await?;
        self.following
            .store(true, std::sync::atomic::Ordering::SeqCst);
        Ok(futures_util::StreamExt::filter_map(
            pubsub.into_on_message(),
            |message| async move {
                let text: String = message.get_payload().ok()?;
                Deleted::parse(&text)
            },
        ))
    }

    /// Records that `owner` shares the build `id` (kept as long as job records are).
    pub async fn join_job(&self, id: &JobId, owner: &str) -> Result<(), Error> {
        let mut conn = self.conn()?;
        let key = job_owners_key(id);
        redis::pipe()
            .atomic()
            .sadd(&key, owner)
            .ignore()
            .expire(&key, RECORD_TTL_S as i64)
            .ignore()
            .query_async::<()>(&mut conn)
            .await
            .map_err(|e| self.error(&e))
    }

    /// Whether `owner` shares the build `id`.
    pub async fn job_owned_by(&self, id: &JobId, owner: &str) -> Result<bool, Error> {
        let mut conn = self.conn()?;
        conn.sismember(job_owners_key(id), owner)
            .await
            .map_err(|e| self.error(&e))
    }

    /// Withdraws `owner` from the build `id`; with the last owner the builder is asked to stop
    /// (atomically). The owners left, or `None` if `owner` was not one.
    pub async fn withdraw_job(&self, id: &JobId, owner: &str) -> Result<Option<usize>, Error> {
        let mut conn = self.conn()?;
        let left: i64 = redis::Script::new(WITHDRAW)
            .key(job_owners_key(id))
            .key(cancel_key(id))
            .arg(owner)
            .arg("set")
            .arg(RECORD_TTL_S)
            .invoke_async(&mut conn)
            .await
            .map_err(|e| self.error(&e))?;
        Ok(usize::try_from(left).ok())
    }

    pub async fn put_job(&self, id: &JobId, record: &impl Serialize) -> Result<(), Error> {
        let mut conn = self.conn()?;
        let json = serde_json::to_string(record).expect("records serialise");
        conn.set_ex::<_, _, ()>(job_key(id), json, RECORD_TTL_S)
            .await
            .map_err(|e| self.error(&e))
    }

    pub async fn request_cancel(&self, id: &JobId) -> Result<(), Error> {
        let mut conn = self.conn()?;
        conn.set_ex::<_, _, ()>(cancel_key(id), 1, RECORD_TTL_S)
            .await
            .map_err(|e| self.error(&e))
    }

    pub async fn cancel_requested(&self, id: &JobId) -> bool {
        let Ok(mut conn) = self.conn() else {
            return false;
        };
        conn.exists(cancel_key(id)).await.unwrap_or(false)
    }

    /// The job a build lock names. Every lock this build takes expires ([`LEASE`], renewed by
    /// its builder's heartbeat); one without an expiry (written by hand, or by a foreign
    /// client) would stall its map's requests forever, so it is given one here.
    async fn lock_holder(
        &self,
        conn: &mut ConnectionManager,
        map_id: &MapId,
    ) -> Result<Option<JobId>, Error> {
        let key = lock_key(map_id);
        let Some(holder) = self.get_or_repair::<String>(conn, &key, "lock").await? else {
            return Ok(None);
        };
        let ttl_ms: i64 = conn.pttl(&key).await.map_err(|e| self.error(&e))?;
        if ttl_ms == -1 {
            let _: redis::RedisResult<bool> = conn.pexpire(&key, LEASE.as_millis() as i64).await;
            tracing::warn!(key, job_id = %holder, "build lock without expiry given one");
            metrics::counter!("irs_redis_repaired_total", "what" => "lock").increment(1);
        }
        Ok(Some(JobId::given(holder)))
    }

    /// Single flight across replicas: the id of the job building `map_id`, and whether it was
    /// started by this call (lock taken, job recorded as queued, entry added to the stream).
    /// `queue_limit` bounds the builds queued or running in the whole cluster (503 past it).
    pub async fn enqueue(
        &self,
        map_id: &MapId,
        key: &MapKey,
        (job_id, queued): (&JobId, &impl Serialize),
        queue_limit: usize,
    ) -> Result<(JobId, bool), Error> {
        let mut conn = self.conn()?;
        for _ in 0..3 {
            if let Some(job_id) = self.lock_holder(&mut conn, map_id).await? {
                return Ok((job_id, false));
            }
            let waiting: usize = conn.xlen(STREAM).await.map_err(|e| self.error(&e))?;
            if waiting >= queue_limit {
                return Err(Error::Full { limit: queue_limit });
            }
            let options = SetOptions::default()
                .conditional_set(ExistenceCheck::NX)
                .with_expiration(SetExpiry::PX(LEASE.as_millis() as u64));
            let taken: Option<String> = conn
                .set_options(lock_key(map_id), job_id.as_str(), options)
                .await
                .map_err(|e| self.error(&e))?;
            if taken.is_none() {
                continue; // another replica took it between the GET and the SET: read it
            }
            let key_json = serde_json::to_string(key).expect("keys serialise");
            let recorded = match self.put_job(job_id, queued).await {
                Ok(()) => conn
                    .xadd::<_, _, _, _, ()>(
                        STREAM,
                        "*",
                        &[
                            ("job_id", job_id.as_str()),
                            ("map_id", map_id.as_str()),
                            ("key", key_json.as_str()),
                        ],
                    )
                    .await
                    .map_err(|e| self.error(&e)),
                Err(e) => Err(e),
            };
            if let Err(e) = recorded {
                // No build will run under this lock: release it rather than let requests wait
                // on a job that never starts until the lock expires.
                let _: redis::RedisResult<()> = conn.del(lock_key(map_id)).await;
                return Err(e);
            }
            return Ok((job_id.clone(), true));
        }
        Err(Error::unavailable(
            "the build lock changed hands three times in a row; retry",
        ))
    }

    /// The next build for this replica: a dead replica's pending entry first, else a new one
    /// (waiting up to [`READ_BLOCK`]). `conn` is the builder's own connection.
    pub async fn next_build(
        &self,
        conn: &mut ConnectionManager,
    ) -> redis::RedisResult<Option<BuildEntry>> {
        // While Redis was away no builder could heartbeat, so every entry looks idle the moment
        // it returns: the live builders get one CLAIM_IDLE to re-claim theirs (and share a map
        // finished meanwhile) before any entry counts as a dead replica's.
        let settled = self
            .up_since
            .lock()
            .expect("cluster lock")
            .is_some_and(|t| t.elapsed() >= CLAIM_IDLE);
        if settled && let Some(entry) = self.claim_idle(conn).await? {
            return Ok(self.accept(conn, &entry).await);
        }
        let options = StreamReadOptions::default()
            .group(GROUP, &self.replica)
            .count(1)
            .block(READ_BLOCK.as_millis() as usize);
        let read: Option<StreamReadReply> = conn.xread_options(&[STREAM], &[">"], &options).await?;
        let entry = read
            .and_then(|r| r.keys.into_iter().next())
            .and_then(|k| k.ids.into_iter().next());
        Ok(match entry {
            Some(entry) => self.accept(conn, &entry).await,
            None => None,
        })
    }

    /// A pending entry idle for [`CLAIM_IDLE`] (its builder stopped), now this replica's.
    async fn claim_idle(
        &self,
        conn: &mut ConnectionManager,
    ) -> redis::RedisResult<Option<StreamId>> {
        let claimed: StreamAutoClaimReply = conn
            .xautoclaim_options(
                STREAM,
                GROUP,
                &self.replica,
                CLAIM_IDLE.as_millis() as u64,
                "0-0",
                StreamAutoClaimOptions::default().count(1),
            )
            .await?;
        let entry = claimed.claimed.into_iter().next();
        if let Some(entry) = &entry {
            tracing::warn!(stream_id = %entry.id, "claimed the build of a replica that stopped");
            metrics::counter!("irs_builds_claimed_total").increment(1);
        }
        Ok(entry)
    }

    /// An entry as a build, or (malformed: not ours to build) acknowledged and dropped.
    async fn accept(&self, conn: &mut ConnectionManager, entry: &StreamId) -> Option<BuildEntry> {
        let build = BuildEntry::of(entry);
        if build.is_none() {
            tracing::warn!(stream_id = %entry.id, "malformed build entry dropped");
            let _: redis::RedisResult<()> = conn.xack(STREAM, GROUP, &[&entry.id]).await;
            let _: redis::RedisResult<()> = conn.xdel(STREAM, &[&entry.id]).await;
        }
        build
    }

    /// Keeps a running build ours: renews the lock and resets the entry's idle time.
    pub async fn heartbeat(&self, build: &BuildEntry) {
        let Ok(mut conn) = self.conn() else { return };
        let _: redis::RedisResult<bool> = conn
            .pexpire(lock_key(&build.map_id), LEASE.as_millis() as i64)
            .await;
        let _: redis::RedisResult<redis::Value> = conn
            .xclaim_options(
                STREAM,
                GROUP,
                &self.replica,
                0,
                &[&build.stream_id],
                StreamClaimOptions::default().with_justid(),
            )
            .await;
    }

    /// Appends a batch of a build's solved rows to its checkpoint, renewing its expiry.
    pub async fn append_checkpoint(&self, map_id: &MapId, batch: &[u8]) -> Result<(), Error> {
        let mut conn = self.conn()?;
        let key = checkpoint_key(map_id);
        redis::pipe()
            .atomic()
            .rpush(&key, batch)
            .ignore()
            .expire(&key, CHECKPOINT_TTL_S)
            .ignore()
            .query_async::<()>(&mut conn)
            .await
            .map_err(|e| self.error(&e))
    }

    /// The batches of solved rows an earlier builder of the map left, oldest first; a key of
    /// another Redis type is deleted and read as none.
    pub async fn checkpoint(&self, map_id: &MapId) -> Result<Vec<Vec<u8>>, Error> {
        let mut conn = self.conn()?;
        let key = checkpoint_key(map_id);
        match conn.lrange::<_, Vec<Vec<u8>>>(&key, 0, -1).await {
            Ok(batches) => Ok(batches),
            Err(e) if e.code() == Some("WRONGTYPE") => {
                self.discard_key(&mut conn, &key, "checkpoint", "wrong Redis type")
                    .await;
                Ok(Vec::new())
            }
            Err(e) => Err(self.error(&e)),
        }
    }

    /// Deletes a checkpoint whose batches do not decode (`why`), logged and counted.
    pub async fn discard_checkpoint(&self, map_id: &MapId, why: &str) {
        let Ok(mut conn) = self.conn() else { return };
        self.discard_key(&mut conn, &checkpoint_key(map_id), "checkpoint", why)
            .await;
    }

    /// Deletes a build's checkpoint (best effort: one Redis cannot take is left to expire).
    pub async fn remove_checkpoint(&self, map_id: &MapId) {
        let Ok(mut conn) = self.conn() else { return };
        let _: redis::RedisResult<()> = conn.del(checkpoint_key(map_id)).await;
    }

    /// A build ended (done, failed or cancelled): the entry is acknowledged and removed, its
    /// checkpoint deleted, the lock released if it is still this job's.
    pub async fn finish(&self, build: &BuildEntry) {
        self.remove_checkpoint(&build.map_id).await;
        let Ok(mut conn) = self.conn() else { return };
        let _: redis::RedisResult<()> = conn.xack(STREAM, GROUP, &[&build.stream_id]).await;
        let _: redis::RedisResult<()> = conn.xdel(STREAM, &[&build.stream_id]).await;
        let holder: Option<String> = conn.get(lock_key(&build.map_id)).await.unwrap_or(None);
        if holder.as_deref() == Some(build.job_id.as_str()) {
            let _: redis::RedisResult<()> = conn.del(lock_key(&build.map_id)).await;
        }
    }
}

fn entry_key(entry: Entry<'_>) -> String {
    match entry {
        Entry::Scenario(id) => scenario_key(id),
        Entry::Map(id) => map_key(id),
        Entry::Job(id) => job_key(id),
    }
}

#[async_trait::async_trait]
impl Store for Cluster {
    fn unavailable(&self) -> Option<String> {
        let down = self.down.lock().expect("cluster lock").clone();
        down.or_else(|| {
            (!self.following.load(std::sync::atomic::Ordering::SeqCst)).then(|| {
                "Redis answers, but the other replicas' deletions are not followed yet".into()
            })
        })
    }

    async fn claim_map(&self, id: &MapId, owner: &str) -> Result<(), Error> {
        let mut conn = self.conn()?;
        conn.sadd::<_, _, ()>(map_owners_key(id), owner)
            .await
            .map_err(|e| self.error(&e))
    }

    async fn map_claimed(&self, id: &MapId, owner: &str) -> Result<bool, Error> {
        let mut conn = self.conn()?;
        conn.sismember(map_owners_key(id), owner)
            .await
            .map_err(|e| self.error(&e))
    }

    async fn withdraw_map(&self, id: &MapId, owner: &str) -> Result<Option<usize>, Error> {
        let mut conn = self.conn()?;
        let left: i64 = redis::Script::new(WITHDRAW)
            .key(map_owners_key(id))
            .key(map_key(id))
            .arg(owner)
            .arg("del")
            .arg(0)
            .invoke_async(&mut conn)
            .await
            .map_err(|e| self.error(&e))?;
        if left == 0 {
            self.announce(&mut conn, Deleted::Map(id.clone())).await;
        }
        Ok(usize::try_from(left).ok())
    }

    /// A key of another Redis type is deleted and read as missing, as is a map whose digest
    /// fails.
    async fn get(&self, entry: Entry<'_>) -> Result<Option<Vec<u8>>, Error> {
        let mut conn = self.conn()?;
        let key = entry_key(entry);
        let Some(bytes) = self
            .get_or_repair::<Vec<u8>>(&mut conn, &key, entry.what())
            .await?
        else {
            return Ok(None);
        };
        let Entry::Map(id) = entry else {
            return Ok(Some(bytes));
        };
        match store::unframe(&bytes) {
            Ok(payload) => {
                // Used now, so the budget evicts it last. Best effort: a failure here costs
                // only the order of a later eviction.
                let touched: redis::RedisResult<u32> = redis::Script::new(TOUCH_MAP)
                    .key(MAP_LRU)
                    .arg(id.as_str())
                    .invoke_async(&mut conn)
                    .await;
                if matches!(&touched, Err(e) if e.code() == Some("WRONGTYPE")) {
                    self.discard_key(&mut conn, MAP_LRU, "map budget", "wrong Redis type")
                        .await;
                }
                Ok(Some(payload.to_vec()))
            }
            Err(reason) => {
                self.discard_key(&mut conn, &key, "map", reason).await;
                Ok(None)
            }
        }
    }

    async fn put_scenario(
        &self,
        id: &ScenarioId,
        record: &(dyn Fn() -> Vec<u8> + Sync),
        replace: bool,
    ) -> Result<(), Error> {
        let mut conn = self.conn()?;
        if !replace {
            let present: bool = conn
                .exists(scenario_key(id))
                .await
                .map_err(|e| self.error(&e))?;
            if present {
                return Ok(());
            }
        }
        conn.set::<_, _, ()>(scenario_key(id), record())
            .await
            .map_err(|e| self.error(&e))
    }

    /// A scenario goes with the maps built from it, and a map with its claims; every replica
    /// is told, so none keeps serving its copy.
    async fn delete(&self, entry: Entry<'_>) -> Result<bool, Error> {
        let mut conn = self.conn()?;
        let (removed, deleted) = match entry {
            Entry::Scenario(id) => {
                let removed: i64 = redis::Script::new(DELETE_SCENARIO)
                    .key(scenario_key(id))
                    .key(scenario_maps_key(id))
                    .arg(MAP_PREFIX)
                    .arg("irs:map-owners:")
                    .invoke_async(&mut conn)
                    .await
                    .map_err(|e| self.error(&e))?;
                (removed > 0, Some(Deleted::Scenario(id.clone())))
            }
            Entry::Map(id) => {
                let removed: usize = conn
                    .del(&[map_key(id), map_owners_key(id)])
                    .await
                    .map_err(|e| self.error(&e))?;
                (removed > 0, Some(Deleted::Map(id.clone())))
            }
            Entry::Job(id) => {
                let removed: usize = conn.del(job_key(id)).await.map_err(|e| self.error(&e))?;
                (removed > 0, None)
            }
        };
        if let Some(deleted) = deleted {
            self.announce(&mut conn, deleted).await;
        }
        Ok(removed)
    }

    async fn discard(&self, entry: Entry<'_>, why: &str) {
        if let Ok(mut conn) = self.conn() {
            self.discard_key(&mut conn, &entry_key(entry), entry.what(), why)
                .await;
        }
    }

    async fn building(&self, map_id: &MapId) -> Result<Option<JobId>, Error> {
        let mut conn = self.conn()?;
        self.lock_holder(&mut conn, map_id).await
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use irs_answers::scenario::ScenarioDocument;
    use irs_model::radiomap::MapKind;
    use irs_model::scenario::Scenario;

    fn entry(fields: &[(&str, &str)]) -> StreamId {
        StreamId {
            id: "1-0".into(),
            map: fields
                .iter()
                .map(|(k, v)| {
                    (
                        k.to_string(),
                        redis::Value::BulkString(v.as_bytes().to_vec()),
                    )
                })
                .collect(),
            ..Default::default()
        }
    }

    /// An entry is a build only if its key hashes to its map id: a replica never builds (and
    /// stores under an id) a map other than the one the entry names.
    #[test]
    fn a_build_entry_must_name_the_map_its_key_defines() {
        let scenario = Scenario::builtin("small-test").unwrap();
        let key = MapKey::new(
            &scenario.content_hash(),
            &scenario,
            MapKind::Gain,
            None,
            None,
            None,
        )
        .unwrap();
        let json = serde_json::to_string(&key).unwrap();
        let id = irs_answers::map::map_id(&key);
        let good = BuildEntry::of(&entry(&[("job_id", "j1"), ("map_id", &id), ("key", &json)]))
            .expect("a well-formed entry");
        assert_eq!((good.job_id.as_str(), good.key), ("j1", key));
        let other = "0".repeat(32);
        for fields in [
            vec![
                ("job_id", "j1"),
                ("map_id", other.as_str()),
                ("key", json.as_str()),
            ],
            vec![
                ("job_id", "j1"),
                ("map_id", id.as_str()),
                ("key", "{\"kind\":1}"),
            ],
            vec![("map_id", id.as_str()), ("key", json.as_str())],
        ] {
            assert!(BuildEntry::of(&entry(&fields)).is_none(), "{fields:?}");
        }
    }
}
