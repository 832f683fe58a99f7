//! Storage below the application. [`Store`] is the state a deployment shares between its
//! nodes, behind one trait with three implementations, so the application asks the same
//! questions whatever runs it:
//!
//! * [`Memory`]: one node, nothing kept across a restart (the default);
//! * [`DataDir`] (`--data-dir`): one node whose claims live in its data directory, next to the
//!   maps, scenarios and jobs it also keeps there ([`disk`]);
//! * [`redis::Cluster`] (`--redis-url`): the store replicas share, where any replica finds the
//!   scenarios, maps, builds and job records of the others.
//!
//! A lone node has no other node: its store holds the claims and answers "not here" for every
//! other replica's scenario, map, build and job (the trait's default methods). The one place
//! the deployment still shows is where a build queues (this node's pool, or the cluster's
//! stream, which only [`redis::Cluster`] has); the application decides that once
//! (`app::maps`, `app::work`).
//!
//! Neither knows HTTP or the application's rules; their refusals are [`Error`]s, which the
//! application maps to its own. Records are the application's JSON; the store keeps their
//! bytes and reads them back as the type it is asked for ([`Store::record`]), so it depends on
//! no type above it.

pub(crate) mod disk;
mod memory;
mod on_disk;
pub(crate) mod redis;

pub(crate) use disk::{DataDir, Kind};
pub(crate) use memory::Memory;

use crate::ids::{JobId, MapId, ScenarioId};
use serde::de::DeserializeOwned;

/// Why the shared store refused.
#[derive(Debug, Clone, thiserror::Error)]
pub(crate) enum Error {
    /// It cannot be used now (down, timing out, or a lock that kept changing hands).
    #[error("{reason}")]
    Unavailable { reason: String },
    /// `limit` builds are already queued or running in the whole cluster.
    #[error("{limit} builds are already queued or running")]
    Full { limit: usize },
    /// The store has no room left (Redis at its `maxmemory`), which waiting does not change.
    #[error("{reason}")]
    NoRoom { reason: String },
}

impl Error {
    pub fn unavailable(reason: impl Into<String>) -> Self {
        Error::Unavailable {
            reason: reason.into(),
        }
    }
}

/// Something the store keeps for every node, by id.
#[derive(Debug, Clone, Copy)]
pub(crate) enum Entry<'a> {
    /// A registered API scenario's record (its canonical document and owner digests).
    Scenario(&'a ScenarioId),
    /// A built map in its compact binary form.
    Map(&'a MapId),
    /// A map build's job record.
    Job(&'a JobId),
}

impl Entry<'_> {
    /// The name of its kind, for logs and the repair counter.
    pub fn what(self) -> &'static str {
        match self {
            Entry::Scenario(_) => "scenario",
            Entry::Map(_) => "map",
            Entry::Job(_) => "job",
        }
    }
}

/// The state the nodes of one deployment share: who claimed each map (with tokens on, a
/// tenant sees only the maps it asked for) and, between replicas, the scenarios, maps, build
/// locks and job records each of them wrote. Owners are digests (never tokens).
#[async_trait::async_trait]
pub(crate) trait Store: Send + Sync {
    /// Why the store cannot be used now, if it cannot (`/readyz` and every request that needs
    /// it answer 503 with the reason).
    fn unavailable(&self) -> Option<String> {
        None
    }

    /// Records that `owner` asked for the map (idempotent).
    async fn claim_map(&self, map_id: &MapId, owner: &str) -> Result<(), Error>;

    /// Whether `owner` asked for the map.
    async fn map_claimed(&self, map_id: &MapId, owner: &str) -> Result<bool, Error>;

    /// Withdraws `owner`'s claim, atomically with deleting the store's copy of the map when it
    /// was the last (a claim made meanwhile elsewhere is never left on a deleted map). The
    /// owners left, or `None` if `owner` had no claim (then nothing changes).
    async fn withdraw_map(&self, map_id: &MapId, owner: &str) -> Result<Option<usize>, Error>;

    /// This node let go of a map (its cache evicted or removed it, or a build ended without
    /// it): a store whose claims describe this node's maps forgets them, unless the map is
    /// still kept where the claims are. A shared store keeps claims with its own copy.
    fn forget_claims(&self, _map_id: &MapId) {}

    /// An entry another node wrote (for a map: the encoded bytes, whose digest checked out).
    async fn get(&self, _entry: Entry<'_>) -> Result<Option<Vec<u8>>, Error> {
        Ok(None)
    }

    /// Publishes an API scenario's record for the other nodes; with `replace` false only when
    /// the store has none yet (a map request must make its scenario readable, not upload a
    /// floor plan each time). `record` makes its bytes, called only by a store that keeps
    /// them (a lone node's registry already has the scenario).
    async fn put_scenario(
        &self,
        _id: &ScenarioId,
        _record: &(dyn Fn() -> Vec<u8> + Sync),
        _replace: bool,
    ) -> Result<(), Error> {
        Ok(())
    }

    /// Deletes an entry (a map with its claims); whether there was one.
    async fn delete(&self, _entry: Entry<'_>) -> Result<bool, Error> {
        Ok(false)
    }

    /// Deletes an entry the application found unusable (a record that is not one of this
    /// build, a map that does not decode to itself), logged and counted, so it is written
    /// again rather than failing every request that meets it.
    async fn discard(&self, _entry: Entry<'_>, _why: &str) {}

    /// The job building `map_id` on some node, as its build lock names it.
    async fn building(&self, _map_id: &MapId) -> Result<Option<JobId>, Error> {
        Ok(None)
    }
}

impl dyn Store + '_ {
    /// A JSON record (a scenario's or a job's) as `R`: one that does not parse is discarded
    /// and read as missing.
    pub async fn record<R: DeserializeOwned>(&self, entry: Entry<'_>) -> Result<Option<R>, Error> {
        let Some(bytes) = self.get(entry).await? else {
            return Ok(None);
        };
        match serde_json::from_slice(&bytes) {
            Ok(record) => Ok(Some(record)),
            Err(e) => {
                self.discard(entry, &e.to_string()).await;
                Ok(None)
            }
        }
    }
}

#[cfg(test)]
mod tests {
    //! The contract every store keeps. Redis's runs against a redis-server this test starts;
    //! it is ignored by `cargo test` (a fresh machine has no Redis) and run by `.ci/run`.
    use super::*;
    use std::sync::Arc;

    fn map(n: u8) -> MapId {
        MapId::given(format!("{n:02x}").repeat(16))
    }

    async fn claims_are_withdrawn_one_owner_at_a_time(store: &dyn Store) {
        let (m, other) = (map(0xab), map(0xcd));
        assert!(!store.map_claimed(&m, "aaaa").await.unwrap());
        store.claim_map(&m, "aaaa").await.unwrap();
        store.claim_map(&m, "bbbb").await.unwrap();
        store.claim_map(&m, "aaaa").await.unwrap();
        assert!(store.map_claimed(&m, "aaaa").await.unwrap());
        assert!(store.map_claimed(&m, "bbbb").await.unwrap());
        assert!(!store.map_claimed(&other, "aaaa").await.unwrap());
        assert_eq!(store.withdraw_map(&m, "aaaa").await.unwrap(), Some(1));
        assert_eq!(
            store.withdraw_map(&m, "aaaa").await.unwrap(),
            None,
            "a claim is withdrawn once"
        );
        assert!(!store.map_claimed(&m, "aaaa").await.unwrap());
        assert!(store.map_claimed(&m, "bbbb").await.unwrap());
        assert_eq!(store.withdraw_map(&m, "bbbb").await.unwrap(), Some(0));
        assert_eq!(store.withdraw_map(&m, "bbbb").await.unwrap(), None);
        assert!(!store.map_claimed(&m, "bbbb").await.unwrap());
    }

    async fn concurrent_claims_all_land(store: Arc<dyn Store>) {
        let m = map(0x34);
        let claims: Vec<_> = (0..16)
            .map(|i| {
                let (store, m) = (store.clone(), m.clone());
                tokio::spawn(async move { store.claim_map(&m, &format!("{i:04x}")).await })
            })
            .collect();
        for claim in claims {
            claim.await.unwrap().unwrap();
        }
        for i in 0..16 {
            assert!(store.map_claimed(&m, &format!("{i:04x}")).await.unwrap());
        }
    }

    /// A lone node forgets the claims of a map it let go of, and has nothing of another node's.
    async fn a_lone_node_is_alone(store: &dyn Store) {
        let m = map(0x56);
        store.claim_map(&m, "cccc").await.unwrap();
        store.forget_claims(&m);
        assert!(!store.map_claimed(&m, "cccc").await.unwrap());
        let id = ScenarioId::given("ab".repeat(16));
        store
            .put_scenario(&id, &|| unreachable!("a lone node keeps no record"), true)
            .await
            .unwrap();
        assert!(store.get(Entry::Scenario(&id)).await.unwrap().is_none());
        assert!(store.get(Entry::Map(&m)).await.unwrap().is_none());
        assert!(!store.delete(Entry::Map(&m)).await.unwrap());
        assert!(store.building(&m).await.unwrap().is_none());
        assert!(store.unavailable().is_none());
    }

    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn memory_keeps_the_contract() {
        let memory = Arc::new(Memory::default());
        claims_are_withdrawn_one_owner_at_a_time(&*memory).await;
        assert!(memory.is_empty(), "nothing kept for a map nobody wants");
        concurrent_claims_all_land(memory.clone()).await;
        a_lone_node_is_alone(&*memory).await;
    }

    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn a_data_dir_keeps_the_contract_and_its_claims_across_a_restart() {
        let root = std::env::temp_dir().join(format!("irs-claims-{}", uuid::Uuid::new_v4()));
        let open = || Arc::new(DataDir::open(&root, 1 << 20, 1 << 20).unwrap());
        claims_are_withdrawn_one_owner_at_a_time(&*open()).await;
        concurrent_claims_all_land(open()).await;
        a_lone_node_is_alone(&*open()).await;
        let m = map(0x12);
        open().claim_map(&m, "aaaa").await.unwrap();
        assert!(
            open().map_claimed(&m, "aaaa").await.unwrap(),
            "a claim survives a restart"
        );
        let _ = std::fs::remove_dir_all(&root);
    }

    /// A replica of the Redis at `port` whose maps may take `budget` bytes, once it follows
    /// the deletions (the subscription lives as long as the returned task).
    async fn replica(port: u16, budget: u64) -> (Arc<redis::Cluster>, tokio::task::JoinHandle<()>) {
        let cluster =
            Arc::new(redis::Cluster::new(&format!("redis://127.0.0.1:{port}"), budget).unwrap());
        let health = cluster.clone();
        let following = cluster.clone();
        let task = tokio::spawn(async move {
            let watch = tokio::spawn(async move { health.watch_health().await });
            while following.up_since().is_none() {
                tokio::time::sleep(std::time::Duration::from_millis(20)).await;
            }
            let stream = following.deletions().await.unwrap();
            use futures_util::StreamExt as _;
            stream.for_each(|_| async {}).await;
            watch.abort();
        });
        let deadline = std::time::Instant::now() + std::time::Duration::from_secs(10);
        while cluster.unavailable().is_some() {
            assert!(std::time::Instant::now() < deadline, "Redis never answered");
            tokio::time::sleep(std::time::Duration::from_millis(20)).await;
        }
        (cluster, task)
    }

    /// Storing a map past the budget evicts the least recently used ones (a read counts as a
    /// use), deleted maps stop counting, and a map bigger than the budget is stored alone.
    async fn maps_stay_within_their_budget(port: u16) {
        let payload = |byte: u8| vec![byte; 100];
        let framed = disk::frame(&payload(0)).len() as u64;
        let (cluster, task) = replica(port, 3 * framed).await;
        let store: &dyn Store = &*cluster;
        let sid = ScenarioId::given("0b".repeat(16));
        let [a, b, c, d, e] = [0xa1, 0xa2, 0xa3, 0xa4, 0xa5].map(map);
        for m in [&a, &b, &c] {
            cluster.put_map(m, &sid, &payload(1)).await.unwrap();
        }
        let present = |ms: Vec<MapId>| async move {
            let mut found = Vec::new();
            for m in ms {
                found.push(store.get(Entry::Map(&m)).await.unwrap().is_some());
            }
            found
        };
        // `a` read now: `b` is the least recently used when `d` needs room.
        assert!(store.get(Entry::Map(&a)).await.unwrap().is_some());
        cluster.put_map(&d, &sid, &payload(2)).await.unwrap();
        assert_eq!(
            present(vec![b.clone(), a.clone(), c.clone(), d.clone()]).await,
            [false, true, true, true],
            "the least recently used map evicted, the others kept"
        );
        // A deleted map frees its room: `e` fits beside `a` and `d`.
        assert!(store.delete(Entry::Map(&c)).await.unwrap());
        cluster.put_map(&e, &sid, &payload(3)).await.unwrap();
        assert_eq!(
            present(vec![a.clone(), d.clone(), e.clone()]).await,
            [true, true, true]
        );
        // Storing a map again replaces its size rather than adding to it.
        cluster.put_map(&e, &sid, &payload(4)).await.unwrap();
        assert_eq!(
            present(vec![a.clone(), d.clone(), e.clone()]).await,
            [true, true, true]
        );
        // Bigger than the whole budget: stored, alone.
        let big = map(0xa6);
        cluster.put_map(&big, &sid, &vec![5; 400]).await.unwrap();
        assert_eq!(
            present(vec![a, d, e, big]).await,
            [false, false, false, true]
        );

        // Redis itself full (a maxmemory below the budget): an error that says so, which
        // retrying does not change, rather than "unavailable, retry".
        let mut conn = cluster.connect().await.unwrap();
        let used: String = ::redis::cmd("INFO")
            .arg("memory")
            .query_async(&mut conn)
            .await
            .unwrap();
        let used: u64 = used
            .lines()
            .find_map(|l| l.strip_prefix("used_memory:"))
            .unwrap()
            .trim()
            .parse()
            .unwrap();
        // A map stored outside the budget (by a build before it) is brought into it when a
        // replica connects.
        let outside = map(0xa8);
        ::redis::cmd("SET")
            .arg(format!("irs:map:{outside}"))
            .arg(disk::frame(&payload(7)))
            .query_async::<()>(&mut conn)
            .await
            .unwrap();
        let (roomy, task_roomy) = replica(port, 1 << 30).await;
        let adopted: bool = ::redis::cmd("HEXISTS")
            .arg("irs:map-sizes")
            .arg(outside.as_str())
            .query_async(&mut conn)
            .await
            .unwrap();
        assert!(adopted, "a map stored outside the budget is counted in it");
        let set_max = |bytes: u64| {
            let mut conn = conn.clone();
            async move {
                ::redis::cmd("CONFIG")
                    .arg("SET")
                    .arg("maxmemory")
                    .arg(bytes)
                    .query_async::<()>(&mut conn)
                    .await
                    .unwrap()
            }
        };
        // Past maxmemory already, as after a write that took Redis over it.
        set_max(used / 2).await;
        let refused = roomy.put_map(&map(0xa7), &sid, &payload(6)).await;
        set_max(0).await;
        assert!(
            matches!(refused, Err(Error::NoRoom { ref reason }) if reason.contains("OOM")),
            "{refused:?}"
        );
        assert_eq!(roomy.unavailable(), None, "full is not down");
        task_roomy.abort();
        task.abort();
    }

    /// Needs `redis-server` on the PATH: `cargo test -p irs-service --lib -- --ignored`.
    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    #[ignore = "starts redis-server; run by .ci/run"]
    async fn redis_keeps_the_contract_and_shares_entries() {
        let port = std::net::TcpListener::bind("127.0.0.1:0")
            .unwrap()
            .local_addr()
            .unwrap()
            .port();
        /// The test's redis-server, stopped however the test ends (a failed assertion too).
        struct Server(std::process::Child);
        impl Drop for Server {
            fn drop(&mut self) {
                let _ = self.0.kill();
                let _ = self.0.wait();
            }
        }
        let _server = Server(
            std::process::Command::new("redis-server")
                .args(["--port", &port.to_string(), "--bind", "127.0.0.1"])
                .args(["--save", "", "--appendonly", "no"])
                .stdout(std::process::Stdio::null())
                .spawn()
                .expect("redis-server on the PATH"),
        );
        let cluster =
            Arc::new(redis::Cluster::new(&format!("redis://127.0.0.1:{port}"), 1 << 20).unwrap());
        let health = cluster.clone();
        let watch = tokio::spawn(async move { health.watch_health().await });
        let deadline = std::time::Instant::now() + std::time::Duration::from_secs(10);
        while cluster.up_since().is_none() {
            assert!(std::time::Instant::now() < deadline, "Redis never answered");
            tokio::time::sleep(std::time::Duration::from_millis(50)).await;
        }
        assert!(
            cluster.unavailable().is_some(),
            "unavailable until the replica follows the deletions"
        );
        use futures_util::StreamExt as _;
        let mut announced = std::pin::pin!(cluster.deletions().await.unwrap());
        assert_eq!(cluster.unavailable(), None);
        let store: Arc<dyn Store> = cluster.clone();
        claims_are_withdrawn_one_owner_at_a_time(&*store).await;
        concurrent_claims_all_land(store.clone()).await;

        // Another replica's scenario record, read back typed; one that is not JSON is
        // discarded and read as missing.
        let id = ScenarioId::given("cd".repeat(16));
        store
            .put_scenario(&id, &|| br#"{"owners":["aaaa"]}"#.to_vec(), true)
            .await
            .unwrap();
        store
            .put_scenario(&id, &|| unreachable!("kept as it is"), false)
            .await
            .unwrap();
        let record: Option<serde_json::Value> = store.record(Entry::Scenario(&id)).await.unwrap();
        assert_eq!(record, Some(serde_json::json!({"owners": ["aaaa"]})));
        store
            .put_scenario(&id, &|| b"not json".to_vec(), true)
            .await
            .unwrap();
        let damaged: Option<serde_json::Value> = store.record(Entry::Scenario(&id)).await.unwrap();
        assert_eq!(damaged, None);
        assert!(
            store.get(Entry::Scenario(&id)).await.unwrap().is_none(),
            "discarded"
        );

        // A map shared by one replica is found by the others, digest checked; the last claim
        // withdrawn deletes it.
        let m = map(0x78);
        cluster.put_map(&m, &id, b"encoded map").await.unwrap();
        assert_eq!(
            store.get(Entry::Map(&m)).await.unwrap().as_deref(),
            Some(&b"encoded map"[..])
        );
        store.claim_map(&m, "aaaa").await.unwrap();
        store.forget_claims(&m);
        assert!(
            store.map_claimed(&m, "aaaa").await.unwrap(),
            "a shared store keeps its claims while it keeps the map"
        );
        assert_eq!(store.withdraw_map(&m, "aaaa").await.unwrap(), Some(0));
        assert!(store.get(Entry::Map(&m)).await.unwrap().is_none());
        cluster.put_map(&m, &id, b"again").await.unwrap();
        assert!(store.delete(Entry::Map(&m)).await.unwrap());
        assert!(!store.delete(Entry::Map(&m)).await.unwrap());
        assert!(store.building(&m).await.unwrap().is_none());

        // A scenario goes with the maps built from it and their claims, a map with its last
        // claim, and every replica is told of each.
        // What the claims and map deletions above announced, heard and set aside.
        let mut earlier = 0;
        while let Ok(Some(_)) =
            tokio::time::timeout(std::time::Duration::from_millis(300), announced.next()).await
        {
            earlier += 1;
        }
        assert!(
            earlier >= 3,
            "the map deletions above were announced ({earlier})"
        );
        let sid = ScenarioId::given("ef".repeat(16));
        store
            .put_scenario(&sid, &|| b"{}".to_vec(), true)
            .await
            .unwrap();
        let (one, two) = (map(0x9a), map(0x9b));
        cluster.put_map(&one, &sid, b"one").await.unwrap();
        cluster.put_map(&two, &sid, b"two").await.unwrap();
        store.claim_map(&two, "aaaa").await.unwrap();
        assert!(store.delete(Entry::Scenario(&sid)).await.unwrap());
        for m in [&one, &two] {
            assert!(store.get(Entry::Map(m)).await.unwrap().is_none(), "{m}");
        }
        assert!(!store.map_claimed(&two, "aaaa").await.unwrap());
        assert!(!store.delete(Entry::Scenario(&sid)).await.unwrap());
        cluster.put_map(&one, &sid, b"one").await.unwrap();
        store.claim_map(&one, "bbbb").await.unwrap();
        assert_eq!(store.withdraw_map(&one, "bbbb").await.unwrap(), Some(0));
        let mut heard = Vec::new();
        while heard.len() < 3 {
            let next = tokio::time::timeout(std::time::Duration::from_secs(5), announced.next());
            heard.push(next.await.expect("announced").expect("subscribed"));
        }
        assert_eq!(
            heard,
            [
                redis::Deleted::Scenario(sid.clone()),
                redis::Deleted::Scenario(sid.clone()),
                redis::Deleted::Map(one.clone())
            ]
        );

        // A build's checkpoint: batches read back in the order appended, with an expiry; a
        // key of another type is repaired and read as no checkpoint.
        let building = map(0xbc);
        assert!(cluster.checkpoint(&building).await.unwrap().is_empty());
        cluster
            .append_checkpoint(&building, b"rows 0-3")
            .await
            .unwrap();
        cluster
            .append_checkpoint(&building, b"rows 4-5")
            .await
            .unwrap();
        assert_eq!(
            cluster.checkpoint(&building).await.unwrap(),
            [b"rows 0-3".to_vec(), b"rows 4-5".to_vec()]
        );
        let mut conn = cluster.connect().await.unwrap();
        let key = format!("irs:checkpoint:{building}");
        let ttl: i64 = ::redis::AsyncCommands::ttl(&mut conn, &key).await.unwrap();
        assert!((3_590..=3_600).contains(&ttl), "expires: {ttl}");
        let _: () = ::redis::AsyncCommands::set(&mut conn, &key, "a string")
            .await
            .unwrap();
        assert!(cluster.checkpoint(&building).await.unwrap().is_empty());
        let left: bool = ::redis::AsyncCommands::exists(&mut conn, &key)
            .await
            .unwrap();
        assert!(!left, "repaired");

        maps_stay_within_their_budget(port).await;

        watch.abort();
    }
}
