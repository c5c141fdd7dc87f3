//! [`ObjectUrl`]: an `s3://bucket/key` URL given where an output's path goes, checked before
//! anything is sent: the bucket's name by S3's rules, the key by the rules every object store
//! shares (no empty, `.` or `..` segment, no control character).

use std::fmt;
use std::path::{Path, PathBuf};

use super::StoreError;

/// The URL scheme of S3-compatible storage (AWS, MinIO, R2, GCS's S3 API, ...).
const SCHEME: &str = "s3://";
/// The longest key S3 takes, in bytes.
const MAX_KEY_BYTES: usize = 1024;

/// An object or a prefix in an S3-compatible bucket: `s3://bucket/key`. For a directory
/// output the key is a prefix (its files are `key/name`); for a file output, the object.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ObjectUrl {
    bucket: String,
    /// Without a leading or trailing `/`; empty for the bucket's root.
    key: String,
}

impl ObjectUrl {
    /// `Some` if `path` is spelt as an object URL (`s3://...`), checked; `None` for a local path.
    pub fn of_path(path: &Path) -> Option<Result<ObjectUrl, StoreError>> {
        let text = path.to_str()?;
        text.get(..SCHEME.len()).filter(|s| s.eq_ignore_ascii_case(SCHEME))?;
        Some(ObjectUrl::parse(text))
    }

    /// Reads `s3://bucket/key` (a trailing `/` is allowed: `s3://bucket/tiles/`).
    pub fn parse(text: &str) -> Result<ObjectUrl, StoreError> {
        let bad = |why: &str| StoreError::Url { url: text.escape_debug().to_string(), why: why.to_string() };
        let rest = match text.get(..SCHEME.len()) {
            Some(s) if s.eq_ignore_ascii_case(SCHEME) => &text[SCHEME.len()..],
            _ => return Err(bad("not an s3:// URL")),
        };
        let (bucket, key) = rest.split_once('/').unwrap_or((rest, ""));
        check_bucket(bucket).map_err(|why| bad(&why))?;
        let key = key.trim_end_matches('/');
        if key.len() > MAX_KEY_BYTES {
            return Err(bad(&format!("the key is {} bytes; S3 takes at most {MAX_KEY_BYTES}", key.len())));
        }
        if !key.is_empty() {
            for segment in key.split('/') {
                match segment {
                    "" => return Err(bad("the key has an empty segment ('//')")),
                    "." | ".." => return Err(bad("the key has a '.' or '..' segment")),
                    s if s.chars().any(char::is_control) => return Err(bad("the key holds a control character")),
                    _ => {}
                }
            }
        }
        Ok(ObjectUrl { bucket: bucket.to_string(), key: key.to_string() })
    }

    /// The bucket's name.
    pub fn bucket(&self) -> &str {
        &self.bucket
    }

    /// The key: the object, or the prefix of a directory output (empty: the bucket's root).
    pub fn key(&self) -> &str {
        &self.key
    }

    /// The key of file `name` ('/'-separated) under this prefix.
    pub fn child(&self, name: &str) -> String {
        match self.key.is_empty() {
            true => name.to_string(),
            false => format!("{}/{name}", self.key),
        }
    }

    /// The URL as the path an [`crate::outputs::Output`] carries.
    pub fn to_path(&self) -> PathBuf {
        PathBuf::from(self.to_string())
    }
}

impl fmt::Display for ObjectUrl {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{SCHEME}{}/{}", self.bucket, self.key)
    }
}

/// S3's rules for a bucket's name: 3 to 63 lower-case letters, digits, dots and hyphens,
/// starting and ending with a letter or digit.
fn check_bucket(name: &str) -> Result<(), String> {
    if name.is_empty() {
        return Err("no bucket: write s3://BUCKET/PREFIX".into());
    }
    if !(3..=63).contains(&name.len()) {
        return Err(format!("the bucket name '{}' is not 3 to 63 characters", name.escape_debug()));
    }
    let allowed = |b: u8| b.is_ascii_lowercase() || b.is_ascii_digit() || b == b'.' || b == b'-';
    let edge = |b: u8| b.is_ascii_lowercase() || b.is_ascii_digit();
    let bytes = name.as_bytes();
    if !bytes.iter().all(|&b| allowed(b)) || !edge(bytes[0]) || !edge(bytes[bytes.len() - 1]) {
        return Err(format!(
            "the bucket name '{}' is not lower-case letters, digits, '.' and '-' (starting and ending with a letter or digit)",
            name.escape_debug()
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn urls_are_read_and_checked() {
        let url = ObjectUrl::parse("s3://my-bucket/tiles/run1/").unwrap();
        assert_eq!((url.bucket(), url.key()), ("my-bucket", "tiles/run1"));
        assert_eq!(url.child("info.json"), "tiles/run1/info.json");
        assert_eq!(url.to_string(), "s3://my-bucket/tiles/run1");
        let root = ObjectUrl::parse("S3://abc").unwrap();
        assert_eq!((root.key(), root.child("a.dzi").as_str()), ("", "a.dzi"));
        for (bad, says) in [
            ("s3:///x", "no bucket"),
            ("s3://ab/x", "3 to 63"),
            ("s3://My_Bucket/x", "lower-case"),
            ("s3://-abc/x", "lower-case"),
            ("s3://abc/a//b", "empty segment"),
            ("s3://abc/a/../b", "'..'"),
            ("s3://abc/a\nb", "control"),
            ("http://abc/x", "not an s3"),
        ] {
            let e = ObjectUrl::parse(bad).unwrap_err().to_string();
            assert!(e.contains(says), "{bad}: {e}");
        }
        assert!(ObjectUrl::of_path(Path::new("out/s3://x")).is_none());
        assert!(ObjectUrl::of_path(Path::new("s3://abc/k")).is_some_and(|u| u.is_ok()));
        let long = format!("s3://abc/{}", "k".repeat(MAX_KEY_BYTES + 1));
        assert!(ObjectUrl::parse(&long).unwrap_err().to_string().contains("at most 1024"));
    }
}
