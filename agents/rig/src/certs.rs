//! `rig certs`: the lab's CA and one certificate per identity of a rig (rcgen), and the
//! check `rig validate` runs on them (x509-parser).
//!
//! Every identity ([`rig_config::identities`]: each joint's board, the hosts, the operator,
//! the recorder, the view, each machine of the plan) gets `<name>.pem` and `<name>.key`, its
//! common name the identity's name, usable as TLS server and client (every Zenoh peer is both),
//! signed by `ca.pem`/`ca.key`. Files already there are kept, so adding a joint and running
//! `rig certs` again signs only the new one with the same CA. docs/SECURITY.md says where each
//! file goes.

use std::path::{Path, PathBuf};

use rcgen::{
    BasicConstraints, CertificateParams, DistinguishedName, DnType, ExtendedKeyUsagePurpose, IsCa,
    Issuer, KeyPair, KeyUsagePurpose,
};
use rig_config::{Identity, RigConfig, SecurityConfig, identities};

use crate::error::CliError;

#[derive(Debug, clap::Args)]
pub struct Args {
    /// Rig config (TOML); its joints and plan name the identities
    #[arg(long, value_name = "FILE")]
    config: PathBuf,
    /// Where to write the CA and the certificates (default: the config's `[security].certs`)
    #[arg(long, value_name = "DIR")]
    out: Option<PathBuf>,
    /// How long the certificates are valid, in days (1 to 36500)
    #[arg(long, value_name = "DAYS", default_value_t = 3650,
          value_parser = clap::value_parser!(u32).range(1..=36500))]
    days: u32,
}

pub fn run(a: &Args) -> Result<(), CliError> {
    let cfg = rig_config::load(&a.config)?;
    let out = match (&a.out, &cfg.security) {
        (Some(o), _) => o.clone(),
        (None, Some(s)) => s.certs.clone(),
        (None, None) => {
            return Err(CliError::Invalid(format!(
                "{} has no [security] section to say where the certificates go: give --out DIR, then add [security] with ca = \"DIR/ca.pem\" and certs = \"DIR\" (docs/SECURITY.md)",
                a.config.display()
            )));
        }
    };
    std::fs::create_dir_all(&out)
        .map_err(|e| CliError::Invalid(format!("--out {}: {e}", out.display())))?;
    let made = make(&cfg, &out, a.days)?;
    for (name, new) in &made {
        println!(
            "{} {}",
            if *new { "made" } else { "kept" },
            out.join(format!("{name}.pem")).display()
        );
    }
    println!(
        "rig certs: {} certificates in {} signed by {}; give each machine ca.pem and its own identities' .pem and .key, keep ca.key off the rig (docs/SECURITY.md)",
        made.len() - 1,
        out.display(),
        out.join("ca.pem").display()
    );
    if cfg.security.is_none() {
        println!(
            "then add to {}:\n[security]\nca = \"{}\"\ncerts = \"{}\"",
            a.config.display(),
            out.join("ca.pem").display(),
            out.display()
        );
    }
    Ok(())
}

/// The validity window: from a day ago (clocks a little behind) for `days` days.
fn validity(p: &mut CertificateParams, days: u32) {
    let now = time::OffsetDateTime::now_utc();
    p.not_before = now - time::Duration::days(1);
    p.not_after = now + time::Duration::days(i64::from(days));
}

fn io(path: &Path) -> impl Fn(std::io::Error) -> CliError + '_ {
    move |e| CliError::Invalid(format!("{}: {e}", path.display()))
}

fn tls(what: &str) -> impl Fn(rcgen::Error) -> CliError + '_ {
    move |e| CliError::Invalid(format!("{what}: {e}"))
}

/// Writes a private key readable by its owner only.
fn write_key(path: &Path, pem: &str) -> Result<(), CliError> {
    use std::io::Write;
    let mut o = std::fs::OpenOptions::new();
    o.write(true).create_new(true);
    #[cfg(unix)]
    std::os::unix::fs::OpenOptionsExt::mode(&mut o, 0o600);
    o.open(path)
        .and_then(|mut f| f.write_all(pem.as_bytes()))
        .map_err(io(path))
}

/// Makes (or keeps) `out/ca.pem` and one certificate per identity of `cfg`; returns the
/// names with whether each was made now (the CA first).
pub fn make(cfg: &RigConfig, out: &Path, days: u32) -> Result<Vec<(String, bool)>, CliError> {
    let (ca_pem, ca_key) = (out.join("ca.pem"), out.join("ca.key"));
    let mut made = Vec::new();
    let (issuer, new_ca) = if ca_pem.is_file() && ca_key.is_file() {
        let key = KeyPair::from_pem(&std::fs::read_to_string(&ca_key).map_err(io(&ca_key))?)
            .map_err(tls("ca.key"))?;
        let pem = std::fs::read_to_string(&ca_pem).map_err(io(&ca_pem))?;
        (
            Issuer::from_ca_cert_pem(&pem, key).map_err(tls("ca.pem"))?,
            false,
        )
    } else if ca_pem.exists() || ca_key.exists() {
        return Err(CliError::Invalid(format!(
            "{} holds one of ca.pem and ca.key but not the other: restore the missing one, or move both away to make a new CA (every certificate must then be made again)",
            out.display()
        )));
    } else {
        let key = KeyPair::generate().map_err(tls("the CA's key"))?;
        let mut p = CertificateParams::default();
        let mut dn = DistinguishedName::new();
        dn.push(DnType::CommonName, format!("{} lab CA", cfg.name));
        p.distinguished_name = dn;
        p.is_ca = IsCa::Ca(BasicConstraints::Constrained(0));
        p.key_usages = vec![KeyUsagePurpose::KeyCertSign, KeyUsagePurpose::CrlSign];
        validity(&mut p, days);
        let cert = p.self_signed(&key).map_err(tls("the CA"))?;
        write_key(&ca_key, &key.serialize_pem())?;
        std::fs::write(&ca_pem, cert.pem()).map_err(io(&ca_pem))?;
        (Issuer::new(p, key), true)
    };
    made.push(("ca".to_string(), new_ca));
    let dirs = SecurityConfig {
        ca: ca_pem.clone(),
        certs: out.to_path_buf(),
    };
    for who in identities(cfg) {
        let name = who.name();
        let (pem, key_path) = (dirs.cert(&who), dirs.key(&who));
        if pem.is_file() && key_path.is_file() {
            made.push((name, false));
            continue;
        }
        let key = KeyPair::generate().map_err(tls(&name))?;
        let mut p = CertificateParams::new(vec!["localhost".to_string(), "127.0.0.1".into()])
            .map_err(tls(&name))?;
        let mut dn = DistinguishedName::new();
        dn.push(DnType::CommonName, name.clone());
        p.distinguished_name = dn;
        p.key_usages = vec![KeyUsagePurpose::DigitalSignature];
        p.extended_key_usages = vec![
            ExtendedKeyUsagePurpose::ServerAuth,
            ExtendedKeyUsagePurpose::ClientAuth,
        ];
        validity(&mut p, days);
        let cert = p.signed_by(&key, &issuer).map_err(tls(&name))?;
        // A half-written pair from an interrupted run is replaced whole.
        let _ = std::fs::remove_file(&key_path);
        write_key(&key_path, &key.serialize_pem())?;
        std::fs::write(&pem, cert.pem()).map_err(io(&pem))?;
        made.push((name, true));
    }
    Ok(made)
}

/// Every problem with `[security]`'s files for `cfg`: the CA readable and a CA; each
/// identity's certificate there, named for it (CN), signed by the CA, valid now, and its key
/// the certificate's. Empty: all good (or no `[security]`).
pub fn check(cfg: &RigConfig) -> Vec<String> {
    let Some(sec) = &cfg.security else {
        return vec![];
    };
    let mut problems = Vec::new();
    let fix = format!(
        "make them with `rig certs --config {}`",
        cfg.source.display()
    );
    let ca_der = match read_pem(&sec.ca) {
        Ok(d) => d,
        Err(e) => return vec![format!("[security].ca: {e}; {fix}")],
    };
    let ca = match x509_parser::parse_x509_certificate(&ca_der) {
        Ok((_, c)) if c.is_ca() => c,
        Ok(_) => {
            return vec![format!(
                "[security].ca: {} is not a CA certificate",
                sec.ca.display()
            )];
        }
        Err(e) => return vec![format!("[security].ca: {}: {e}", sec.ca.display())],
    };
    for who in identities(cfg) {
        if let Err(e) = check_identity(sec, &who, &ca) {
            problems.push(format!("identity {}: {e}", who.name()));
        }
    }
    if problems.iter().any(|p| p.contains("missing")) {
        problems.push(fix);
    }
    problems
}

fn read_pem(path: &Path) -> Result<Vec<u8>, String> {
    let text = std::fs::read(path)
        .map_err(|e| format!("{} is missing or unreadable: {e}", path.display()))?;
    let (_, pem) = x509_parser::pem::parse_x509_pem(&text)
        .map_err(|e| format!("{} is not a PEM certificate: {e}", path.display()))?;
    Ok(pem.contents)
}

fn check_identity(
    sec: &SecurityConfig,
    who: &Identity,
    ca: &x509_parser::certificate::X509Certificate<'_>,
) -> Result<(), String> {
    let (pem, key) = (sec.cert(who), sec.key(who));
    let der = read_pem(&pem)?;
    let (_, cert) =
        x509_parser::parse_x509_certificate(&der).map_err(|e| format!("{}: {e}", pem.display()))?;
    let cn = cert
        .subject()
        .iter_common_name()
        .next()
        .and_then(|c| c.as_str().ok())
        .unwrap_or("");
    if cn != who.name() {
        return Err(format!(
            "{} is made out to {cn:?}, not {:?}",
            pem.display(),
            who.name()
        ));
    }
    cert.verify_signature(Some(ca.public_key())).map_err(|_| {
        format!(
            "{} is not signed by the lab CA {}",
            pem.display(),
            sec.ca.display()
        )
    })?;
    if !cert.validity().is_valid() {
        return Err(format!(
            "{} is not valid now (from {} to {})",
            pem.display(),
            cert.validity().not_before,
            cert.validity().not_after
        ));
    }
    let key_text = std::fs::read_to_string(&key)
        .map_err(|e| format!("{} is missing or unreadable: {e}", key.display()))?;
    let pair = KeyPair::from_pem(&key_text).map_err(|e| format!("{}: {e}", key.display()))?;
    if pair.public_key_raw() != cert.public_key().subject_public_key.data.as_ref() {
        return Err(format!(
            "{} is not the key of {}",
            key.display(),
            pem.display()
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The parallel example with `[security]` pointing into a fresh directory of its own.
    fn lab(tag: &str) -> (RigConfig, PathBuf) {
        let dir = std::env::temp_dir().join(format!("rig-certs-{tag}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        let mut cfg = rig_config::examples::load("parallel").unwrap();
        cfg.security = Some(SecurityConfig {
            ca: dir.join("ca.pem"),
            certs: dir.clone(),
        });
        (cfg, dir)
    }

    #[test]
    fn certs_made_for_a_rig_pass_the_check_and_each_kind_of_wrong_file_is_named() {
        let (cfg, dir) = lab("check");
        let made = make(&cfg, &dir, 30).unwrap();
        assert_eq!(made.len(), identities(&cfg).len() + 1);
        assert!(made.iter().all(|(_, new)| *new));
        assert_eq!(check(&cfg), Vec::<String>::new());

        // Run again: everything kept; a lost pair is made again with the same CA.
        std::fs::remove_file(dir.join("viz.pem")).unwrap();
        let again = make(&cfg, &dir, 30).unwrap();
        let new: Vec<&str> = again
            .iter()
            .filter(|(_, new)| *new)
            .map(|(n, _)| n.as_str())
            .collect();
        assert_eq!(new, ["viz"]);
        assert_eq!(check(&cfg), Vec::<String>::new());

        // Another lab's certificate in the estimator's place: not signed by this CA.
        let (other_cfg, other) = lab("other");
        make(&other_cfg, &other, 30).unwrap();
        std::fs::copy(other.join("estimator.pem"), dir.join("estimator.pem")).unwrap();
        std::fs::copy(other.join("estimator.key"), dir.join("estimator.key")).unwrap();
        // The allocator's key swapped for the operator's: not the certificate's key.
        std::fs::copy(dir.join("operator.key"), dir.join("allocator.key")).unwrap();
        // The viewer's certificate made out to someone else.
        std::fs::copy(dir.join("recorder.pem"), dir.join("viz.pem")).unwrap();
        // A joint's key gone.
        std::fs::remove_file(dir.join("joint-j2.key")).unwrap();
        let problems = check(&cfg);
        let has = |who: &str, what: &str| {
            problems
                .iter()
                .any(|p| p.starts_with(&format!("identity {who}:")) && p.contains(what))
        };
        assert!(
            has("estimator", "is not signed by the lab CA"),
            "{problems:#?}"
        );
        assert!(has("allocator", "is not the key of"), "{problems:#?}");
        assert!(has("viz", "is made out to \"recorder\""), "{problems:#?}");
        assert!(has("joint-j2", "missing"), "{problems:#?}");
        assert!(
            problems.last().unwrap().contains("rig certs"),
            "{problems:#?}"
        );
        assert_eq!(problems.len(), 5, "{problems:#?}");

        // Half a CA is refused rather than replaced (every certificate would change).
        std::fs::remove_file(other.join("ca.key")).unwrap();
        let e = make(&other_cfg, &other, 30).unwrap_err().to_string();
        assert!(e.contains("ca.pem and ca.key"), "{e}");
        let _ = std::fs::remove_dir_all(&dir);
        let _ = std::fs::remove_dir_all(&other);
    }
}
