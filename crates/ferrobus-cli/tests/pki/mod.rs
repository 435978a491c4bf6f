//! Certificates for the Modbus/TCP Security tests, made with rcgen into a directory of the
//! test's own: a CA, a server certificate for 127.0.0.1 and localhost, and client
//! certificates with a role extension (1.3.6.1.4.1.50316.802.1) in the encoding asked for,
//! or none.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU32, Ordering};

use rcgen::{
    BasicConstraints, CertificateParams, CustomExtension, DnType, ExtendedKeyUsagePurpose, IsCa, KeyPair,
    KeyUsagePurpose,
};

/// The role extension's OID.
const ROLE_OID: &[u64] = &[1, 3, 6, 1, 4, 1, 50316, 802, 1];

/// A DER UTF8String's tag: the role's encoding.
pub(crate) const UTF8_STRING: u8 = 0x0C;
/// A DER OCTET STRING's tag: a wrong encoding seen in examples.
#[allow(dead_code, reason = "shared by two test binaries; the cli one uses only the right encoding")]
pub(crate) const OCTET_STRING: u8 = 0x04;

/// A certificate file and its key file.
pub(crate) struct Pair {
    /// The certificate (PEM).
    pub(crate) cert: PathBuf,
    /// Its key (PEM, PKCS#8).
    pub(crate) key: PathBuf,
}

/// A CA in its own directory (removed on drop), and what it issues.
pub(crate) struct Pki {
    dir: PathBuf,
    ca: rcgen::Certificate,
    ca_key: KeyPair,
}

impl Pki {
    /// A fresh CA named `name`; its certificate is [`Pki::ca`].
    pub(crate) fn new(name: &str) -> Pki {
        static NEXT: AtomicU32 = AtomicU32::new(0);
        let n = NEXT.fetch_add(1, Ordering::Relaxed);
        let dir = std::env::temp_dir().join(format!("ferrobus-pki-{}-{n}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap_or_else(|e| panic!("making {}: {e}", dir.display()));
        let mut params = CertificateParams::new(Vec::<String>::new()).unwrap();
        params.distinguished_name.push(DnType::CommonName, name);
        params.is_ca = IsCa::Ca(BasicConstraints::Unconstrained);
        params.key_usages = vec![KeyUsagePurpose::KeyCertSign, KeyUsagePurpose::DigitalSignature];
        let ca_key = KeyPair::generate().unwrap();
        let ca = params.self_signed(&ca_key).unwrap();
        std::fs::write(dir.join("ca.pem"), ca.pem()).unwrap();
        Pki { dir, ca, ca_key }
    }

    /// The directory the files are in.
    pub(crate) fn dir(&self) -> &Path {
        &self.dir
    }

    /// The CA's certificate file.
    pub(crate) fn ca(&self) -> PathBuf {
        self.dir.join("ca.pem")
    }

    /// A server certificate for 127.0.0.1 and localhost.
    pub(crate) fn server(&self) -> Pair {
        self.issue("server", true, Vec::new())
    }

    /// A client certificate named `name` with the role `role` encoded with DER tag `tag`
    /// ([`UTF8_STRING`] is right), or without a role.
    pub(crate) fn client(&self, name: &str, role: Option<(u8, &str)>) -> Pair {
        let extensions = role
            .map(|(tag, role)| {
                let mut content = vec![tag, u8::try_from(role.len()).unwrap()];
                content.extend_from_slice(role.as_bytes());
                CustomExtension::from_oid_content(ROLE_OID, content)
            })
            .into_iter()
            .collect();
        self.issue(name, false, extensions)
    }

    fn issue(&self, name: &str, server: bool, extensions: Vec<CustomExtension>) -> Pair {
        let mut params = CertificateParams::new(vec!["localhost".to_string(), "127.0.0.1".to_string()]).unwrap();
        params.distinguished_name.push(DnType::CommonName, name);
        params.extended_key_usages =
            vec![if server { ExtendedKeyUsagePurpose::ServerAuth } else { ExtendedKeyUsagePurpose::ClientAuth }];
        params.custom_extensions = extensions;
        let key = KeyPair::generate().unwrap();
        let cert = params.signed_by(&key, &self.ca, &self.ca_key).unwrap();
        let pair = Pair { cert: self.dir.join(format!("{name}.pem")), key: self.dir.join(format!("{name}.key")) };
        std::fs::write(&pair.cert, cert.pem()).unwrap();
        std::fs::write(&pair.key, key.serialize_pem()).unwrap();
        pair
    }
}

impl Drop for Pki {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.dir);
    }
}
