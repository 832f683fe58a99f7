//! Persistence on one node (`serve --data-dir DIR`): the scenarios registered through the API,
//! the built maps and the finished job records, as files that survive a restart.
//!
//! Layout: `DIR/scenarios/<scenario id>.rec`, `DIR/maps/<map id>.rec`, `DIR/jobs/<job id>.rec`,
//! and `DIR/map-owners/<map id>.rec` (the owner digests of a map, with tokens on); a map's
//! owners file goes whenever its map file goes, so no claim outlives its map.
//! Scenario and map files are content-addressed (the id is the hash of the scenario's
//! canonical form, or of the map key), so a file can only ever hold one content; a job record
//! is rewritten only when the job ends.
//!
//! Every file is `MAGIC`, the SHA-256 of the payload, then the payload (JSON for scenarios and
//! jobs, [`irs_answers::encoding`] for maps), written to a temporary file in the same
//! directory, flushed to disk and renamed over the target: a reader sees the old file or the
//! new one, never half of one. A file whose digest or content does not check out (a torn write
//! from before this scheme, a disk error, an edit) is skipped with a warning and never served;
//! the map is then built again on request.
//!
//! Maps on disk are bounded by `--data-maps-mb`: past it, the least recently written go first.
//! The memory cache stays in front (a map read from disk enters it), so the disk is read once
//! per map and restart, not per query.
//!
//! Files are read with their type and size checked first (docs/deployment.md "Data
//! directory"): only regular files (a FIFO would block start-up, a device never end), no map
//! file larger than the largest map this server keeps (the smaller of the data directory's
//! and the memory cache's budgets) and no JSON record larger than the largest scenario file.
//! A map file found damaged when it is loaded is removed (logged once), so it is not read
//! again on every request for it; the map is built again instead.
//!
//! A directory that cannot be written (read-only, full) does not stop the service: it starts,
//! serves what it can read, and reports the directory in `/readyz` until a write probe
//! ([`DataDir::probe`], every few seconds) succeeds again.

use irs_answers::encoding;
use irs_model::radiomap::RadioMap;
use irs_model::scenario::Scenario;
use sha2::{Digest, Sha256};
use std::collections::HashMap;
use std::fs;
use std::io::{Read, Write};
use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::SystemTime;

/// Largest JSON record (a scenario or a job) read back: the largest scenario file, since a
/// record holds at most one scenario document in its canonical form.
const MAX_JSON_RECORD_BYTES: u64 =
    irs_answers::files::MAX_SCENARIO_FILE_BYTES + HEADER_BYTES as u64;

/// The first bytes of every file: the format's name and version.
const MAGIC: &[u8; 8] = b"IRSREC\x00\x01";
const HEADER_BYTES: usize = MAGIC.len() + 32;
const EXTENSION: &str = "rec";

/// Which kind of record, and the directory it lives in.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Kind {
    Scenario,
    Map,
    Job,
    /// Who asked for a map (`store::on_disk`).
    MapOwners,
    /// The rows an interrupted rate-map build had solved, by map id
    /// (`irs_answers::encoding::encode_rows`), which its resumption copies.
    Checkpoint,
}

impl Kind {
    fn dir(self) -> &'static str {
        match self {
            Kind::Scenario => "scenarios",
            Kind::Map => "maps",
            Kind::Job => "jobs",
            Kind::MapOwners => "map-owners",
            Kind::Checkpoint => "checkpoints",
        }
    }
}

/// What the store knows about a map file without reading it again.
#[derive(Debug, Clone)]
struct MapFile {
    scenario_id: String,
    bytes: u64,
    written: SystemTime,
}

/// A data directory, opened.
pub(crate) struct DataDir {
    root: PathBuf,
    /// The maps on disk, for the byte budget and for deleting a scenario's maps.
    maps: Mutex<HashMap<String, MapFile>>,
    maps_budget_bytes: u64,
    /// Largest map file written or read (header included): the smaller of the maps' disk
    /// budget and the memory cache's, as a larger map is never written and could not be held.
    max_map_file_bytes: u64,
    /// Why the directory cannot be written, as the last write probe found; `None` when it can.
    unwritable: Mutex<Option<String>>,
    /// Distinguishes the temporary files of concurrent writes.
    writes: AtomicU64,
    /// Serialises each read-modify-write of a map's claims (`store::on_disk`).
    pub(super) claims_serial: Mutex<()>,
}

/// Ids are lower-case hex (content hashes, UUIDs without dashes): nothing else is a file name.
fn valid_id(id: &str) -> bool {
    !id.is_empty() && id.len() <= 128 && id.bytes().all(|b| b.is_ascii_hexdigit())
}

/// Frames a payload with the magic bytes and its digest (files, and maps in Redis).
pub(crate) fn frame(payload: &[u8]) -> Vec<u8> {
    let mut out = Vec::with_capacity(HEADER_BYTES + payload.len());
    out.extend_from_slice(MAGIC);
    out.extend_from_slice(&Sha256::digest(payload));
    out.extend_from_slice(payload);
    out
}

/// The payload of a framed record, if the frame and the digest check out.
pub(crate) fn unframe(bytes: &[u8]) -> Result<&[u8], &'static str> {
    if bytes.len() < HEADER_BYTES || &bytes[..MAGIC.len()] != MAGIC {
        return Err("not a record of this format (magic bytes differ)");
    }
    let (digest, payload) = bytes[MAGIC.len()..].split_at(32);
    if Sha256::digest(payload).as_slice() != digest {
        return Err("the digest does not match the content (torn or damaged file)");
    }
    Ok(payload)
}

impl DataDir {
    /// Opens (creating if needed) the directory. Maps are kept on disk up to
    /// `maps_budget_bytes`, none larger than `cache_bytes` (the memory cache's budget). Only a
    /// root that does not exist and cannot be created is an error (naming the path and the
    /// reason): one that exists but cannot be written (read-only, full) is opened for reading,
    /// with a warning, and reported by [`DataDir::unwritable`].
    pub fn open(root: &Path, maps_budget_bytes: u64, cache_bytes: u64) -> Result<DataDir, String> {
        fs::create_dir_all(root).map_err(|e| format!("--data-dir {}: {e}", root.display()))?;
        for kind in [
            Kind::Scenario,
            Kind::Map,
            Kind::Job,
            Kind::MapOwners,
            Kind::Checkpoint,
        ] {
            let dir = root.join(kind.dir());
            if let Err(e) = fs::create_dir_all(&dir) {
                // The probe below reports it; what can be read is still served.
                tracing::warn!(dir = %dir.display(), error = %e, "data directory: cannot create");
            }
            // Temporary files of writes a crash interrupted: never renamed, never valid.
            for entry in fs::read_dir(&dir).into_iter().flatten().flatten() {
                if entry.file_name().to_string_lossy().starts_with(".tmp-") {
                    let _ = fs::remove_file(entry.path());
                }
            }
        }
        let store = DataDir {
            root: root.to_path_buf(),
            maps: Mutex::new(HashMap::new()),
            maps_budget_bytes,
            max_map_file_bytes: maps_budget_bytes.min(cache_bytes),
            unwritable: Mutex::new(None),
            writes: AtomicU64::new(0),
            claims_serial: Mutex::new(()),
        };
        // A write test now, so an operator sees at start-up that writes will fail.
        if let Err(reason) = store.probe() {
            tracing::warn!(dir = %root.display(), reason, "data directory not writable: serving what it holds, degraded until it can be written");
        }
        let mut maps = HashMap::new();
        // Only each file's head (the key) is read now; the digest is checked when a map is
        // loaded, so opening a directory of gigabytes takes milliseconds.
        for (id, path) in store.ids(Kind::Map) {
            let opened = irs_answers::files::open_regular(&path).and_then(|(file, meta)| {
                let mut head = Vec::with_capacity(4096);
                file.take(4096).read_to_end(&mut head)?;
                Ok((head, meta))
            });
            let (head, meta) = match opened {
                Ok(opened) => opened,
                Err(e) => {
                    tracing::warn!(file = %path.display(), error = %e, "map file not readable; ignored");
                    continue;
                }
            };
            if meta.len() > store.max_map_file_bytes {
                // Never written by this configuration (a damaged file, or a lower budget than
                // the one it was written under): never read whole either.
                tracing::warn!(file = %path.display(), bytes = meta.len(), limit = store.max_map_file_bytes, "map file larger than the largest map kept; ignored");
                continue;
            }
            let key = match head.get(..MAGIC.len()) {
                Some(magic) if magic == MAGIC => head
                    .get(HEADER_BYTES..)
                    .ok_or_else(|| "shorter than its header".to_string())
                    .and_then(|payload| encoding::peek_key(payload).map_err(|e| e.to_string())),
                _ => Err("not a record of this format (magic bytes differ)".to_string()),
            };
            match key {
                Ok(key) if irs_answers::map::map_id(&key) == id => {
                    maps.insert(
                        id,
                        MapFile {
                            scenario_id: key.scenario_id,
                            bytes: meta.len(),
                            written: meta.modified().unwrap_or(SystemTime::UNIX_EPOCH),
                        },
                    );
                }
                Ok(_) => {
                    tracing::warn!(file = %path.display(), "map file holds another map's key; ignored")
                }
                Err(e) => {
                    tracing::warn!(file = %path.display(), error = %e, "map file not readable by this build; ignored")
                }
            }
        }
        tracing::info!(dir = %root.display(), maps = maps.len(), "data directory opened");
        *store.maps.lock().expect("store lock") = maps;
        Ok(store)
    }

    fn path(&self, kind: Kind, id: &str) -> PathBuf {
        self.root.join(kind.dir()).join(format!("{id}.{EXTENSION}"))
    }

    /// The ids of the record files of `kind`, with their paths. A record name on anything but
    /// a regular file (a FIFO, a directory, a device) is skipped with a warning: opening a FIFO
    /// would wait for a writer for ever.
    fn ids(&self, kind: Kind) -> Vec<(String, PathBuf)> {
        let Ok(entries) = fs::read_dir(self.root.join(kind.dir())) else {
            return Vec::new();
        };
        let mut ids: Vec<(String, PathBuf)> = entries
            .flatten()
            .filter_map(|e| {
                let path = e.path();
                let id = path.file_stem()?.to_str()?.to_string();
                (path.extension()? == EXTENSION && valid_id(&id)).then_some((id, path))
            })
            .filter(|(_, path)| match fs::metadata(path) {
                Ok(meta) if meta.is_file() => true,
                Ok(meta) => {
                    let kind = irs_answers::files::file_kind(&meta.file_type());
                    tracing::warn!(file = %path.display(), kind, "data directory: not a regular file; skipped");
                    false
                }
                Err(e) => {
                    tracing::warn!(file = %path.display(), error = %e, "data directory: not readable; skipped");
                    false
                }
            })
            .collect();
        ids.sort();
        ids
    }

    /// Probes whether the directory takes writes now: a small temporary file written, flushed
    /// to disk and removed (a full disk fails the write or the flush). The answer is kept for
    /// [`DataDir::unwritable`]. Blocking: called at open and from a background task.
    pub fn probe(&self) -> Result<(), String> {
        let n = self.writes.fetch_add(1, Ordering::Relaxed);
        let temporary = self
            .root
            .join(Kind::Job.dir())
            .join(format!(".tmp-probe-{}-{n}", std::process::id()));
        let result = (|| {
            let mut file = fs::File::create(&temporary)?;
            file.write_all(&frame(b"probe"))?;
            file.sync_all()
        })();
        let _ = fs::remove_file(&temporary);
        let result = result.map_err(|e| format!("{}: {e}", temporary.display()));
        let mut unwritable = self.unwritable.lock().expect("store lock");
        match (&result, unwritable.is_some()) {
            (Err(reason), false) => {
                tracing::warn!(dir = %self.root.display(), reason, "data directory no longer writable")
            }
            (Ok(()), true) => {
                tracing::info!(dir = %self.root.display(), "data directory writable again")
            }
            _ => {}
        }
        *unwritable = result.clone().err();
        metrics::gauge!("irs_data_dir_writable").set(if result.is_ok() { 1.0 } else { 0.0 });
        result
    }

    /// Why the directory could not be written at the last probe or write, if it could not.
    pub fn unwritable(&self) -> Option<String> {
        self.unwritable.lock().expect("store lock").clone()
    }

    /// A write failed: reported as unwritable at once, until the next probe succeeds.
    fn write_failed(&self, error: &std::io::Error) {
        *self.unwritable.lock().expect("store lock") =
            Some(format!("{}: {error}", self.root.display()));
        metrics::gauge!("irs_data_dir_writable").set(0.0);
    }

    /// Writes a record atomically: a temporary file, flushed, renamed over the target.
    fn write(&self, kind: Kind, id: &str, payload: &[u8]) -> std::io::Result<()> {
        debug_assert!(valid_id(id));
        let target = self.path(kind, id);
        let n = self.writes.fetch_add(1, Ordering::Relaxed);
        let temporary = self
            .root
            .join(kind.dir())
            .join(format!(".tmp-{id}-{}-{n}", std::process::id()));
        let result = (|| {
            let mut file = fs::File::create(&temporary)?;
            file.write_all(&frame(payload))?;
            file.sync_all()?;
            fs::rename(&temporary, &target)
        })();
        if result.is_err() {
            let _ = fs::remove_file(&temporary);
        }
        result
    }

    /// A record's payload, or `None` (with a warning) if it is missing, not a regular file,
    /// larger than records of its kind can be, torn or damaged.
    fn read(&self, kind: Kind, id: &str) -> Option<Vec<u8>> {
        let path = self.path(kind, id);
        let max_bytes = match kind {
            // A checkpoint holds at most the rows of one map.
            Kind::Map | Kind::Checkpoint => self.max_map_file_bytes,
            Kind::Scenario | Kind::Job | Kind::MapOwners => MAX_JSON_RECORD_BYTES,
        };
        let bytes = match irs_answers::files::read_regular(&path, max_bytes) {
            Ok(bytes) => bytes,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return None,
            Err(e) => {
                tracing::warn!(file = %path.display(), error = %e, "record not readable; ignored");
                return None;
            }
        };
        match unframe(&bytes) {
            Ok(payload) => Some(payload.to_vec()),
            Err(reason) => {
                metrics::counter!("irs_store_corrupt_total", "kind" => kind.dir()).increment(1);
                tracing::warn!(file = %path.display(), reason, "record ignored");
                None
            }
        }
    }

    fn remove(&self, kind: Kind, id: &str) {
        if valid_id(id) {
            let _ = fs::remove_file(self.path(kind, id));
        }
    }

    /// Saves a JSON record (a scenario or a job); a failure is logged, not fatal: the service
    /// keeps serving from memory.
    pub fn save_json(&self, kind: Kind, id: &str, value: &impl serde::Serialize) {
        let payload = serde_json::to_vec(value).expect("records serialise");
        if let Err(e) = self.write(kind, id, &payload) {
            metrics::counter!("irs_store_write_errors_total", "kind" => kind.dir()).increment(1);
            tracing::warn!(id, kind = kind.dir(), error = %e, "could not persist a record");
            self.write_failed(&e);
        }
    }

    pub fn remove_json(&self, kind: Kind, id: &str) {
        self.remove(kind, id);
    }

    /// One JSON record, if it is there and readable (a damaged one is skipped with a warning).
    pub fn load_one_json<T: serde::de::DeserializeOwned>(&self, kind: Kind, id: &str) -> Option<T> {
        if !valid_id(id) {
            return None;
        }
        let payload = self.read(kind, id)?;
        serde_json::from_slice(&payload)
            .inspect_err(|e| tracing::warn!(id, kind = kind.dir(), error = %e, "record ignored"))
            .ok()
    }

    /// Every readable JSON record of `kind`, with its id; unreadable ones are skipped.
    pub fn load_json<T: serde::de::DeserializeOwned>(&self, kind: Kind) -> Vec<(String, T)> {
        self.ids(kind)
            .into_iter()
            .filter_map(|(id, path)| {
                let payload = self.read(kind, &id)?;
                match serde_json::from_slice(&payload) {
                    Ok(value) => Some((id, value)),
                    Err(e) => {
                        tracing::warn!(file = %path.display(), error = %e, "record ignored");
                        None
                    }
                }
            })
            .collect()
    }

    /// Saves the rows an interrupted build solved (encoded), replacing any earlier ones; a
    /// failure is logged (the resumed build solves those rows again).
    pub fn save_checkpoint(&self, map_id: &str, rows: &[u8]) {
        if !valid_id(map_id) {
            return;
        }
        if let Err(e) = self.write(Kind::Checkpoint, map_id, rows) {
            metrics::counter!("irs_store_write_errors_total", "kind" => Kind::Checkpoint.dir())
                .increment(1);
            tracing::warn!(map_id, error = %e, "could not persist a build's checkpoint");
            self.write_failed(&e);
        }
    }

    /// The rows [`DataDir::save_checkpoint`] kept for a map, if readable.
    pub fn load_checkpoint(&self, map_id: &str) -> Option<Vec<u8>> {
        valid_id(map_id)
            .then(|| self.read(Kind::Checkpoint, map_id))
            .flatten()
    }

    pub fn remove_checkpoint(&self, map_id: &str) {
        self.remove(Kind::Checkpoint, map_id);
    }

    /// Saves a built map, then drops the least recently written maps past the budget.
    pub fn save_map(&self, map_id: &str, map: &RadioMap) {
        let payload = encoding::encode(map);
        if payload.len() as u64 + HEADER_BYTES as u64 > self.max_map_file_bytes {
            tracing::info!(
                map_id,
                bytes = payload.len(),
                limit = self.max_map_file_bytes,
                "map larger than the largest map file kept (the data directory's or the cache's budget); not written"
            );
            return;
        }
        if let Err(e) = self.write(Kind::Map, map_id, &payload) {
            metrics::counter!("irs_store_write_errors_total", "kind" => "maps").increment(1);
            tracing::warn!(map_id, error = %e, "could not persist a map");
            self.write_failed(&e);
            return;
        }
        let mut maps = self.maps.lock().expect("store lock");
        maps.insert(
            map_id.to_string(),
            MapFile {
                scenario_id: map.key.scenario_id.clone(),
                bytes: (payload.len() + HEADER_BYTES) as u64,
                written: SystemTime::now(),
            },
        );
        let mut held: u64 = maps.values().map(|m| m.bytes).sum();
        if held > self.maps_budget_bytes {
            let mut oldest: Vec<(SystemTime, String, u64)> = maps
                .iter()
                .filter(|(id, _)| id.as_str() != map_id)
                .map(|(id, m)| (m.written, id.clone(), m.bytes))
                .collect();
            oldest.sort();
            for (_, id, bytes) in oldest {
                if held <= self.maps_budget_bytes {
                    break;
                }
                self.remove(Kind::Map, &id);
                self.remove(Kind::MapOwners, &id);
                maps.remove(&id);
                held -= bytes;
                tracing::info!(map_id = %id, "map dropped from the data directory (budget)");
            }
        }
        metrics::gauge!("irs_store_map_bytes").set(held as f64);
    }

    /// A stored map, decoded against its scenario (`scenario_of` finds it by id); `None` if
    /// there is none, or it is damaged (then removed), or its scenario is not registered.
    pub fn load_map(
        &self,
        map_id: &str,
        scenario_of: impl Fn(&str) -> Option<std::sync::Arc<Scenario>>,
    ) -> Option<RadioMap> {
        let scenario_id = self
            .maps
            .lock()
            .expect("store lock")
            .get(map_id)?
            .scenario_id
            .clone();
        let scenario = scenario_of(&scenario_id)?;
        let decoded = match self.read(Kind::Map, map_id) {
            Some(payload) => encoding::decode(&payload, &scenario).map_err(|e| e.to_string()),
            None => Err("not readable (logged above)".to_string()),
        };
        match decoded {
            Ok(map) if map.id == map_id => Some(map),
            failed => {
                let reason = failed.err().unwrap_or_else(|| "holds another map".into());
                // Removed, so the next request for it builds it instead of reading it again.
                self.remove_map(map_id);
                tracing::warn!(
                    map_id,
                    reason,
                    "map file damaged; removed (built again on request)"
                );
                None
            }
        }
    }

    pub fn remove_map(&self, map_id: &str) -> bool {
        let known = self
            .maps
            .lock()
            .expect("store lock")
            .remove(map_id)
            .is_some();
        self.remove(Kind::Map, map_id);
        self.remove(Kind::MapOwners, map_id);
        known
    }

    /// Drops every stored map of a scenario (it was deleted).
    pub fn remove_maps_of(&self, scenario_id: &str) {
        let ids: Vec<String> = self
            .maps
            .lock()
            .expect("store lock")
            .iter()
            .filter(|(_, m)| m.scenario_id == scenario_id)
            .map(|(id, _)| id.clone())
            .collect();
        for id in ids {
            self.remove_map(&id);
        }
    }

    /// The stored maps' ids, most recently written first.
    pub fn map_ids(&self) -> Vec<String> {
        let maps = self.maps.lock().expect("store lock");
        let mut ids: Vec<(SystemTime, String)> =
            maps.iter().map(|(id, m)| (m.written, id.clone())).collect();
        ids.sort_by(|a, b| b.cmp(a));
        ids.into_iter().map(|(_, id)| id).collect()
    }

    pub fn has_map(&self, map_id: &str) -> bool {
        self.maps.lock().expect("store lock").contains_key(map_id)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn temporary_dir(name: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("irs-store-{name}-{}", std::process::id()));
        let _ = fs::remove_dir_all(&dir);
        dir
    }

    #[test]
    fn a_damaged_or_torn_record_is_never_read() {
        let dir = temporary_dir("damaged");
        let store = DataDir::open(&dir, 1 << 20, 1 << 20).unwrap();
        store.save_json(Kind::Job, "ab12", &serde_json::json!({"state": "done"}));
        let loaded: Vec<(String, serde_json::Value)> = store.load_json(Kind::Job);
        assert_eq!(loaded.len(), 1);
        let path = store.path(Kind::Job, "ab12");
        let good = fs::read(&path).unwrap();
        // One flipped bit, a truncation, and another format's bytes.
        let mut flipped = good.clone();
        *flipped.last_mut().unwrap() ^= 1;
        for bad in [
            flipped,
            good[..good.len() - 3].to_vec(),
            b"{\"state\":1}".to_vec(),
        ] {
            fs::write(&path, &bad).unwrap();
            let loaded: Vec<(String, serde_json::Value)> = store.load_json(Kind::Job);
            assert!(loaded.is_empty());
        }
        // Interrupted writes leave temporary files, removed on the next open; files that are
        // not records are not read.
        fs::write(dir.join("jobs/.tmp-ab12-1-0"), b"half").unwrap();
        fs::write(dir.join("jobs/notes.txt"), b"hello").unwrap();
        let _ = DataDir::open(&dir, 1 << 20, 1 << 20).unwrap();
        assert!(!dir.join("jobs/.tmp-ab12-1-0").exists());
        let _ = fs::remove_dir_all(&dir);
    }

    fn mkfifo(path: &Path) {
        let c = std::ffi::CString::new(path.to_str().unwrap()).unwrap();
        // SAFETY: a valid NUL-terminated path.
        assert_eq!(unsafe { libc::mkfifo(c.as_ptr(), 0o600) }, 0);
    }

    /// The small floor's gain map and its scenario.
    fn small_gain_map() -> (std::sync::Arc<Scenario>, RadioMap) {
        use irs_answers::scenario::ScenarioDocument;
        use irs_model::radiomap::{MapKey, MapKind, Progress};
        let scenario = std::sync::Arc::new(Scenario::builtin("small-test").unwrap());
        let id = scenario.content_hash();
        let key = MapKey::new(&id, &scenario, MapKind::Gain, None, None, None).unwrap();
        let map = irs_answers::map::build(&scenario, &key, &Progress::default()).unwrap();
        (scenario, map)
    }

    #[test]
    fn fifos_and_directories_with_record_names_are_skipped_not_opened() {
        let dir = temporary_dir("fifo");
        let store = DataDir::open(&dir, 1 << 20, 1 << 20).unwrap();
        store.save_json(Kind::Job, "ab12", &serde_json::json!({"state": "done"}));
        drop(store);
        // Opened as plain files, the FIFOs would block `open` and `load_json` for ever.
        mkfifo(&dir.join("jobs/cd34.rec"));
        mkfifo(&dir.join(format!("maps/{}.rec", "ef".repeat(16))));
        fs::create_dir(dir.join("scenarios/0123.rec")).unwrap();
        let store = DataDir::open(&dir, 1 << 20, 1 << 20).unwrap();
        assert!(store.map_ids().is_empty());
        let jobs: Vec<(String, serde_json::Value)> = store.load_json(Kind::Job);
        assert_eq!(jobs.len(), 1, "the regular record is still read");
        let scenarios: Vec<(String, serde_json::Value)> = store.load_json(Kind::Scenario);
        assert!(scenarios.is_empty());
        // A FIFO put in place of a known record is refused when read, too.
        fs::remove_file(store.path(Kind::Job, "ab12")).unwrap();
        mkfifo(&store.path(Kind::Job, "ab12"));
        assert!(store.read(Kind::Job, "ab12").is_none());
        let _ = fs::remove_dir_all(&dir);
    }

    #[test]
    fn a_damaged_map_is_read_once_then_removed_and_an_oversized_one_never() {
        let dir = temporary_dir("damaged-map");
        let (scenario, map) = small_gain_map();
        let lookup = |_: &str| Some(scenario.clone());
        let store = DataDir::open(&dir, 1 << 30, 1 << 30).unwrap();
        store.save_map(&map.id, &map);
        let path = store.path(Kind::Map, &map.id);
        let mut bytes = fs::read(&path).unwrap();
        *bytes.last_mut().unwrap() ^= 1;
        fs::write(&path, &bytes).unwrap();
        assert!(store.load_map(&map.id, lookup).is_none());
        assert!(!path.exists(), "removed once found damaged");
        assert!(!store.has_map(&map.id), "and forgotten: never read again");

        // A file past the largest map kept (here the cache's budget) is not indexed at open,
        // so no request reads it; one that grows past it after is refused unread.
        store.save_map(&map.id, &map);
        let good = fs::read(&path).unwrap();
        let small_cache = good.len() as u64 - 1;
        let store = DataDir::open(&dir, 1 << 30, small_cache).unwrap();
        assert!(!store.has_map(&map.id));
        let store = DataDir::open(&dir, 1 << 30, good.len() as u64).unwrap();
        assert!(store.has_map(&map.id));
        let mut grown = good.clone();
        grown.push(0);
        fs::write(&path, &grown).unwrap();
        assert!(store.read(Kind::Map, &map.id).is_none());
        let _ = fs::remove_dir_all(&dir);
    }

    #[test]
    fn a_directory_that_cannot_be_written_opens_and_says_why() {
        let dir = temporary_dir("unwritable");
        let store = DataDir::open(&dir, 1 << 20, 1 << 20).unwrap();
        store.save_json(Kind::Scenario, "ab12", &serde_json::json!({"kept": true}));
        assert_eq!(store.unwritable(), None);
        // A file where the jobs directory should be: every write there fails, whoever runs the
        // test (permissions do not stop root).
        fs::remove_dir_all(dir.join("jobs")).unwrap();
        fs::write(dir.join("jobs"), b"in the way").unwrap();
        let store = DataDir::open(&dir, 1 << 20, 1 << 20).expect("opens anyway");
        let reason = store.unwritable().expect("reported");
        assert!(reason.contains("jobs"), "{reason}");
        let kept: Vec<(String, serde_json::Value)> = store.load_json(Kind::Scenario);
        assert_eq!(kept.len(), 1, "what it holds is still read");
        // Writable again: the next probe says so.
        fs::remove_file(dir.join("jobs")).unwrap();
        fs::create_dir(dir.join("jobs")).unwrap();
        assert_eq!(store.probe(), Ok(()));
        assert_eq!(store.unwritable(), None);
        // A failed write reports it at once, before any probe.
        fs::remove_dir_all(dir.join("jobs")).unwrap();
        fs::write(dir.join("jobs"), b"in the way").unwrap();
        store.save_json(Kind::Job, "cd34", &serde_json::json!({}));
        assert!(store.unwritable().is_some());
        let _ = fs::remove_dir_all(&dir);
    }

    #[test]
    fn maps_past_the_budget_go_oldest_first() {
        use irs_answers::map::build;
        use irs_answers::scenario::ScenarioDocument;
        use irs_model::radiomap::{MapKey, MapKind, Progress};
        let dir = temporary_dir("budget");
        let scenario = std::sync::Arc::new(Scenario::builtin("small-test").unwrap());
        let id = scenario.content_hash();
        let gain = build(
            &scenario,
            &MapKey::new(&id, &scenario, MapKind::Gain, None, None, None).unwrap(),
            &Progress::default(),
        )
        .unwrap();
        let bits = build(
            &scenario,
            &MapKey::new(
                &id,
                &scenario,
                MapKind::Gain,
                Some(irs_model::phases::PhaseMode::Bits(1)),
                None,
                None,
            )
            .unwrap(),
            &Progress::default(),
        )
        .unwrap();
        let one = encoding::encode(&gain).len() as u64 + HEADER_BYTES as u64;
        // Room for one map and a half: the second write drops the first.
        let store = DataDir::open(&dir, one * 3 / 2, u64::MAX).unwrap();
        store.save_map(&gain.id, &gain);
        std::thread::sleep(std::time::Duration::from_millis(20));
        store.save_map(&bits.id, &bits);
        assert_eq!(store.map_ids(), vec![bits.id.clone()]);
        let lookup = |sid: &str| (sid == id).then(|| scenario.clone());
        let back = store.load_map(&bits.id, lookup).expect("stored");
        assert_eq!(back.values.len(), bits.values.len());
        assert!(store.load_map(&gain.id, lookup).is_none());
        // Reopened, the directory knows its maps again.
        let store = DataDir::open(&dir, one * 3 / 2, u64::MAX).unwrap();
        assert_eq!(store.map_ids(), vec![bits.id.clone()]);
        assert!(
            store.load_map(&bits.id, |_| None).is_none(),
            "needs its scenario"
        );
        let _ = fs::remove_dir_all(&dir);
    }
}
