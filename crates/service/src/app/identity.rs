//! Identity: bearer tokens and ownership (off unless tokens are configured). Who a request's
//! caller is ([`Tokens::caller`]) is decided here; `http::auth` only reads the header and turns
//! a refusal into a 401.
//!
//! With tokens set (`--api-tokens`, `--api-tokens-file`), every `POST` and `DELETE` needs
//! `Authorization: Bearer <token>` (401 otherwise): they start builds and searches, register
//! scenarios and cancel work, and even a path query may build its map. Reads stay open, as the
//! ids they take are content hashes or random.
//!
//! Reads stay open to callers without a token for what belongs to nobody (the built-in and file
//! scenarios); everything a tenant made — maps it asked for, jobs, placements, API scenarios —
//! is seen and touched only by the tokens that asked for it ([`Owners`]), and anybody else gets
//! 404 exactly as for an id that does not exist, so content-hash ids reveal nothing.
//!
//! A token is never stored in a record or a log: an owner is named by the first 16 hex digits
//! of the token's SHA-256.

use super::Error;
use sha2::{Digest, Sha256};
use std::collections::{BTreeSet, HashMap};
use std::path::Path;
use std::sync::Arc;

/// Who made a record: the digest of a token.
#[derive(Debug, Clone, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub(crate) struct Owner(Arc<str>);

impl Owner {
    /// An owner as a data directory recorded it (the digest [`Owner::of`] makes).
    pub(crate) fn from_digest(digest: String) -> Owner {
        Owner(digest.into())
    }

    fn of(token: &str) -> Owner {
        let digest = Sha256::digest(token.as_bytes());
        let hex: String = digest[..8].iter().map(|b| format!("{b:02x}")).collect();
        Owner(hex.into())
    }
}

impl std::fmt::Display for Owner {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

/// The owners of something several tenants may ask for (a map, a shared build): each asked for
/// it, each may withdraw its own interest, and the thing goes with the last of them. Ordered, so
/// records list them the same way every time.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub(crate) struct Owners(BTreeSet<Owner>);

impl Owners {
    /// One owner, or nobody (authentication off).
    pub fn of(owner: Option<Owner>) -> Owners {
        Owners(owner.into_iter().collect())
    }

    /// Owners as a record keeps them (digests); an unreadable entry cannot name a token.
    pub fn from_digests(digests: impl IntoIterator<Item = String>) -> Owners {
        Owners(digests.into_iter().map(Owner::from_digest).collect())
    }

    /// The digests, sorted, as records write them.
    pub fn digests(&self) -> Vec<String> {
        self.0.iter().map(Owner::to_string).collect()
    }

    /// Adds an owner; true if it was not one already.
    pub fn insert(&mut self, owner: Owner) -> bool {
        self.0.insert(owner)
    }

    /// Removes an owner; true if it was one.
    pub fn remove(&mut self, owner: &Owner) -> bool {
        self.0.remove(owner)
    }

    pub fn contains(&self, owner: &Owner) -> bool {
        self.0.contains(owner)
    }

    pub fn len(&self) -> usize {
        self.0.len()
    }

    /// The first owner (a record's `owner`, kept for readers of the older format).
    pub fn first(&self) -> Option<&Owner> {
        self.0.iter().next()
    }
}

/// The tokens the server accepts (empty: authentication off).
#[derive(Debug, Default)]
pub(crate) struct Tokens {
    owners: HashMap<String, Owner>,
}

/// Shortest token accepted: 16 characters, so a configured token is not guessable by trying.
const MIN_TOKEN_CHARS: usize = 16;

impl Tokens {
    /// The tokens given on the command line and in `file` (one per line, `#` comments).
    pub fn load(listed: &[String], file: Option<&Path>) -> Result<Tokens, String> {
        let mut all: Vec<String> = listed.iter().map(|t| t.trim().to_string()).collect();
        if let Some(path) = file {
            let text = std::fs::read_to_string(path)
                .map_err(|e| format!("--api-tokens-file {}: {e}", path.display()))?;
            all.extend(
                text.lines()
                    .map(str::trim)
                    .filter(|l| !l.is_empty() && !l.starts_with('#'))
                    .map(str::to_string),
            );
        }
        all.retain(|t| !t.is_empty());
        if let Some(short) = all.iter().position(|t| t.chars().count() < MIN_TOKEN_CHARS) {
            return Err(format!(
                "API token #{} is shorter than {MIN_TOKEN_CHARS} characters",
                short + 1
            ));
        }
        if let Some(bad) = all
            .iter()
            .position(|t| !t.bytes().all(|b| b.is_ascii_graphic()))
        {
            return Err(format!(
                "API token #{} has characters outside printable ASCII",
                bad + 1
            ));
        }
        Ok(Tokens {
            owners: all
                .into_iter()
                .map(|token| {
                    let owner = Owner::of(&token);
                    (token, owner)
                })
                .collect(),
        })
    }

    pub fn enabled(&self) -> bool {
        !self.owners.is_empty()
    }

    pub fn count(&self) -> usize {
        self.owners.len()
    }

    /// The caller presenting `authorization` (the header's value, if any) for a request that
    /// `writes` or only reads. Refused: a token this server does not accept, and a write
    /// without a token while authentication is on.
    pub fn caller(&self, authorization: Option<&str>, writes: bool) -> Result<Caller, Error> {
        if !self.enabled() {
            return Ok(Caller::Open);
        }
        let caller = match authorization {
            None => Caller::Anonymous,
            Some(value) => {
                let token = value
                    .strip_prefix("Bearer ")
                    .or_else(|| value.strip_prefix("bearer "));
                match token.and_then(|t| self.owners.get(t.trim())) {
                    Some(owner) => Caller::Owner(owner.clone()),
                    None => {
                        metrics::counter!("irs_auth_failures_total").increment(1);
                        return Err(Error::Unauthorized(
                            "the bearer token is not one this server accepts".into(),
                        ));
                    }
                }
            }
        };
        if writes && caller == Caller::Anonymous {
            return Err(Error::Unauthorized(
                "this server requires a bearer token for POST and DELETE: send Authorization: Bearer <token>".into(),
            ));
        }
        Ok(caller)
    }
}

/// Who is calling, as the handlers see it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) enum Caller {
    /// Authentication is off: no ownership, everything visible (the development set-up).
    Open,
    /// Authentication is on and the request carried no token (reads only).
    Anonymous,
    /// A valid token.
    Owner(Owner),
}

impl Caller {
    /// The owner to record on what this caller creates.
    pub fn owner(&self) -> Option<Owner> {
        match self {
            Caller::Owner(o) => Some(o.clone()),
            Caller::Open | Caller::Anonymous => None,
        }
    }

    /// May this caller see or change something `owners` asked for? With authentication on,
    /// only one of them may: a caller without a claim is told it does not exist.
    pub fn may_touch_any(&self, owners: &Owners) -> bool {
        match self {
            Caller::Open => true,
            Caller::Anonymous => false,
            Caller::Owner(me) => owners.contains(me),
        }
    }
}
