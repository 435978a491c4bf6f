//! The profile a backup is made, compared or restored with: a `--device` profile with the name
//! it was given and, for a file, the hash that pins the exact file.

use ferrobus_profile::{BUILTIN, Point, Profile};
use ferrobus_proto::ExceptionCode;

use super::sha256;

/// How the device identifies itself, as the profile says.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub(crate) enum Identification {
    /// FC2B/0E Read Device Identification.
    DeviceId,
    /// FC11 Report Server ID.
    ServerId,
    /// Neither.
    None,
}

/// A loaded profile, with its name and hash.
#[derive(Clone, Debug)]
pub(crate) struct View {
    /// The name it was loaded by: a built-in name or a file's path.
    pub(crate) name: String,
    /// `sha256:…` of the file, for a profile that is not built in.
    pub(crate) hash: Option<String>,
    /// The profile.
    pub(crate) profile: Profile,
}

impl View {
    /// Loads a built-in profile by name or a profile file.
    pub(crate) fn load(name: &str) -> Result<View, String> {
        let profile = Profile::load(name).map_err(|e| e.to_string())?;
        let hash = if BUILTIN.iter().any(|(n, _)| *n == name) {
            None
        } else {
            let bytes = std::fs::read(name).map_err(|e| format!("cannot read profile {name}: {e}"))?;
            Some(format!("sha256:{}", sha256::hex(&bytes)))
        };
        Ok(View { name: name.to_string(), hash, profile })
    }

    /// The device's name in the profile.
    pub(crate) fn device(&self) -> &str {
        &self.profile.device.name
    }

    /// The point called `code` (case-insensitively).
    pub(crate) fn find(&self, code: &str) -> Option<&Point> {
        self.profile.point(code)
    }

    /// The readable points the profile marks for backup, in the profile's order.
    pub(crate) fn backed_up(&self) -> Vec<&Point> {
        self.profile.points().iter().filter(|p| p.backup && p.readable()).collect()
    }

    /// The device's meaning of an exception code: the profile's `[[exception_meaning]]`, or
    /// for a vendor code the role `[exceptions]` gives it.
    pub(crate) fn meaning(&self, code: u8) -> Option<&str> {
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
    pub(crate) fn identification(&self) -> Identification {
        if self.profile.device.identification {
            Identification::DeviceId
        } else if self.profile.device.server_id.is_some() {
            Identification::ServerId
        } else {
            Identification::None
        }
    }

    /// The point that tells whether the drive runs, and its raw values that mean running.
    pub(crate) fn running(&self) -> Option<(&Point, &[i64])> {
        let rule = self.profile.state.running.as_ref()?;
        Some((self.find(&rule.point)?, rule.values.as_slice()))
    }
}
