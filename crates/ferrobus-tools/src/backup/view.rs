//! The profile a backup is made, compared or restored with: a `--device` profile with the name
//! it was given and, for a file, the hash that pins the exact file.

use std::fmt::Write as _;

use ferrobus_profile::{BUILTIN, Point, Profile, ProfileError};
use ferrobus_proto::ExceptionCode;
use sha2::{Digest, Sha256};

/// Why a profile could not be loaded for a backup.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ViewError {
    /// The profile does not load (not found, not valid).
    #[error(transparent)]
    Profile(#[from] ProfileError),
    /// The profile file loaded, but could not be read again to hash it.
    #[error("cannot read profile {name}: {source}")]
    Read {
        /// The path.
        name: String,
        /// Why.
        source: std::io::Error,
    },
}

/// How the device identifies itself, as the profile says.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub enum Identification {
    /// FC2B/0E Read Device Identification.
    DeviceId,
    /// FC11 Report Server ID.
    ServerId,
    /// Neither.
    None,
}

/// A loaded profile, with its name and hash.
#[derive(Clone, Debug)]
pub struct View {
    /// The name it was loaded by: a built-in name or a file's path.
    pub name: String,
    /// `sha256:…` of the file, for a profile that is not built in.
    pub hash: Option<String>,
    /// The profile.
    pub profile: Profile,
}

impl View {
    /// Loads a built-in profile by name or a profile file.
    pub fn load(name: &str) -> Result<View, ViewError> {
        let profile = Profile::load(name)?;
        let hash = if BUILTIN.iter().any(|(n, _)| *n == name) {
            None
        } else {
            let bytes = std::fs::read(name).map_err(|source| ViewError::Read { name: name.to_string(), source })?;
            Some(format!("sha256:{}", sha256_hex(&bytes)))
        };
        Ok(View { name: name.to_string(), hash, profile })
    }

    /// The device's name in the profile.
    pub fn device(&self) -> &str {
        &self.profile.device.name
    }

    /// The point called `code` (case-insensitively).
    pub fn find(&self, code: &str) -> Option<&Point> {
        self.profile.point(code)
    }

    /// The readable points the profile marks for backup, in the profile's order.
    pub fn backed_up(&self) -> Vec<&Point> {
        self.profile.points().iter().filter(|p| p.backup && p.readable()).collect()
    }

    /// The device's meaning of an exception code: the profile's `[[exception_meaning]]`, or
    /// for a vendor code the role `[exceptions]` gives it.
    pub fn meaning(&self, code: u8) -> Option<&str> {
        if let Some(meaning) = self.profile.exception_meaning(code) {
            return Some(meaning);
        }
        if !matches!(ExceptionCode::from_u8(code), ExceptionCode::Vendor(_)) {
            return None;
        }
        let e = &self.profile.exceptions;
        if code == e.out_of_range {
            Some("the profile's code for a value out of the device's range")
        } else if code == e.not_allowed || code == e.read_only {
            Some("the profile's code for a write the device does not allow now (read-only, or while running)")
        } else {
            None
        }
    }

    /// How the device identifies itself.
    pub fn identification(&self) -> Identification {
        if self.profile.device.identification {
            Identification::DeviceId
        } else if self.profile.device.server_id.is_some() {
            Identification::ServerId
        } else {
            Identification::None
        }
    }

    /// The point that tells whether the drive runs, and its raw values that mean running.
    pub fn running(&self) -> Option<(&Point, &[i64])> {
        let rule = self.profile.state.running.as_ref()?;
        Some((self.find(&rule.point)?, rule.values.as_slice()))
    }
}

/// The SHA-256 of `bytes`, in lower-case hex.
fn sha256_hex(bytes: &[u8]) -> String {
    Sha256::digest(bytes).iter().fold(String::with_capacity(64), |mut out, byte| {
        let _ = write!(out, "{byte:02x}");
        out
    })
}

#[cfg(test)]
mod tests {
    use super::sha256_hex;

    #[test]
    fn a_file_is_named_by_its_sha_256_as_fips_180_gives_it() {
        assert_eq!(sha256_hex(b""), "e3b0c44298fc1c149afbf4c8996fb92427ae41e4649b934ca495991b7852b855");
        assert_eq!(sha256_hex(b"abc"), "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad");
    }
}
