//! The on-disk Lipschitz cache: one small JSON file per operator fingerprint.

use crate::model::op::Operator;
use crate::solve::lipschitz::{Eigen, EigenStore, Fingerprint};
use std::path::{Path, PathBuf};

/// On-disk cache of measured eigenvalues, one small JSON file per fingerprint.
pub struct LipschitzCache {
    dir: Option<PathBuf>,
}

impl LipschitzCache {
    /// `$ROLLCAM_CACHE_DIR`, else `$XDG_CACHE_HOME/rollcam`, else `~/.cache/rollcam`;
    /// `ROLLCAM_CACHE_DIR=off` disables caching.
    pub fn default_location() -> Self {
        let dir = match std::env::var_os("ROLLCAM_CACHE_DIR") {
            Some(v) if v == "off" => None,
            Some(v) => Some(PathBuf::from(v)),
            None => std::env::var_os("XDG_CACHE_HOME")
                .map(|x| PathBuf::from(x).join("rollcam"))
                .or_else(|| std::env::var_os("HOME").map(|h| PathBuf::from(h).join(".cache").join("rollcam"))),
        };
        LipschitzCache { dir: dir.map(|d| d.join("lipschitz")) }
    }

    pub fn at(dir: &Path) -> Self {
        LipschitzCache { dir: Some(dir.to_path_buf()) }
    }

    pub fn disabled() -> Self {
        LipschitzCache { dir: None }
    }

    fn path(&self, key: &Fingerprint) -> Option<PathBuf> {
        self.dir.as_ref().map(|d| d.join(format!("{}.json", key.hex())))
    }

    /// The cached eigenvalue for `key`, or measure it (and store it).
    pub fn get_or_measure(&self, key: Fingerprint, op: &dyn Operator) -> (Eigen, bool) {
        EigenStore::get_or_measure(self, key, op)
    }
}

impl EigenStore for LipschitzCache {
    fn load(&self, key: &Fingerprint) -> Option<Eigen> {
        let path = self.path(key)?;
        if !path.exists() {
            return None;
        }
        // A regular file of bounded size holding a JSON object of the entry's fields;
        // anything else (a FIFO, `/dev/zero`, `[1, 2, 3]`) is ignored aloud and measured.
        let entry = crate::io::input::read_text(&path).map_err(|e| e.to_string()).and_then(|text| match serde_json::from_str::<serde_json::Value>(&text) {
            Ok(v) if v.is_object() => serde_json::from_value::<Eigen>(v).map_err(|e| e.to_string()),
            Ok(_) => Err("not a JSON object".into()),
            Err(e) => Err(e.to_string()),
        });
        match entry {
            Ok(e) => Some(e),
            Err(err) => {
                tracing::warn!(path = %path.display(), %err, "a malformed Lipschitz cache entry is ignored (measured again)");
                None
            }
        }
    }

    fn store(&self, key: &Fingerprint, e: &Eigen) {
        let Some(p) = self.path(key) else { return };
        let write = || -> std::io::Result<()> {
            std::fs::create_dir_all(p.parent().unwrap())?;
            let tmp = p.with_extension(format!("tmp{}", std::process::id()));
            std::fs::write(&tmp, serde_json::to_string(e).unwrap())?;
            std::fs::rename(&tmp, &p)
        };
        if let Err(err) = write() {
            tracing::warn!(path = %p.display(), %err, "could not cache the Lipschitz constant");
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::op::{pseudo_random, Dense};

    #[test]
    fn cache_returns_the_stored_value() {
        let dir = tempfile::tempdir().unwrap();
        let cache = LipschitzCache::at(dir.path());
        let a = Dense { rows: 4, cols: 3, a: pseudo_random(12, 8) };
        let key = Fingerprint::default().f32s(&a.a);
        let (e1, hit1) = cache.get_or_measure(key, &a);
        let (e2, hit2) = cache.get_or_measure(key, &a);
        assert!(!hit1 && hit2);
        assert_eq!(e1, e2);
        let other = Fingerprint::default().f32s(&a.a).usize(1);
        assert_ne!(other.hex(), key.hex());
    }
}
