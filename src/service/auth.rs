//! Tenants: bearer tokens → tenant names, shared by REST and gRPC.
//!
//! Why it exists: a lab shares one server; each client sees only its own jobs (another
//! tenant's job id answers 404, never 403, so ids leak nothing). Tokens come from
//! `--tokens tenant:token,...` (env `PHYSNAP_TOKENS`) or a file with one `tenant token` pair a
//! line. With no tokens configured every request is the tenant `local`; `serve` allows that
//! only when every public listener is on a loopback address.

use crate::error::Invalid;
use std::collections::HashMap;
use std::path::Path;

use super::jobs::ServiceError;

/// The tenant of unauthenticated requests in no-auth mode.
pub const ANONYMOUS_TENANT: &str = "local";

/// Token table.
#[derive(Debug, Clone, Default)]
pub struct Tenants {
    by_token: HashMap<String, String>,
}

impl Tenants {
    /// Parse `tenant:token` pairs (comma-separated) and, optionally, a file of `tenant token`
    /// lines (`#` comments). An error names the entry (`--tokens entry 2`, `--tokens-file
    /// PATH line 3`), the rule and what was there (tokens redacted).
    pub fn load(inline: &str, file: Option<&Path>) -> Result<Tenants, Invalid> {
        let mut t = Tenants::default();
        for (i, pair) in inline
            .split(',')
            .map(str::trim)
            .filter(|p| !p.is_empty())
            .enumerate()
        {
            let at = format!("--tokens entry {i}");
            let (tenant, token) = pair.split_once(':').ok_or_else(|| {
                Invalid::new(
                    &at,
                    "tenant:token",
                    format!("{} characters without ':'", pair.len()),
                )
            })?;
            t.add(tenant.trim(), token.trim(), &at)?;
        }
        if let Some(path) = file {
            let text = std::fs::read_to_string(path).map_err(|e| {
                Invalid::new(
                    "--tokens-file",
                    "a readable file",
                    format!("{}: {e}", path.display()),
                )
            })?;
            for (n, line) in text.lines().enumerate() {
                let line = line.trim();
                if line.is_empty() || line.starts_with('#') {
                    continue;
                }
                let at = format!("--tokens-file {} line {}", path.display(), n + 1);
                let fields: Vec<&str> = line.split_whitespace().collect();
                let [tenant, token] = fields[..] else {
                    return Err(Invalid::new(
                        at,
                        "`tenant token`",
                        format!("{} fields", fields.len()),
                    ));
                };
                t.add(tenant, token, &at)?;
            }
        }
        Ok(t)
    }

    fn add(&mut self, tenant: &str, token: &str, at: &str) -> Result<(), Invalid> {
        if tenant.is_empty() || token.len() < 8 {
            return Err(Invalid::new(
                at,
                "a non-empty tenant and a token of at least 8 characters",
                format!("tenant {tenant:?}, a token of {} characters", token.len()),
            ));
        }
        if self
            .by_token
            .insert(token.to_string(), tenant.to_string())
            .is_some()
        {
            return Err(Invalid::new(
                at,
                "a token no other entry has",
                "a duplicate token",
            ));
        }
        Ok(())
    }

    /// Whether no tokens are configured (no-auth mode).
    pub fn is_open(&self) -> bool {
        self.by_token.is_empty()
    }

    /// Tenant names (for the start-up log; never the tokens).
    pub fn tenant_names(&self) -> Vec<String> {
        let mut v: Vec<String> = self.by_token.values().cloned().collect();
        v.sort();
        v.dedup();
        v
    }

    /// The tenant of an `authorization` header value (`Bearer <token>`).
    pub fn resolve(&self, authorization: Option<&str>) -> Result<String, ServiceError> {
        if self.is_open() {
            return Ok(ANONYMOUS_TENANT.to_string());
        }
        let token = authorization
            .and_then(|h| {
                h.strip_prefix("Bearer ")
                    .or_else(|| h.strip_prefix("bearer "))
            })
            .map(str::trim)
            .ok_or_else(|| {
                ServiceError::Unauthenticated("missing `authorization: Bearer <token>`".into())
            })?;
        self.by_token
            .get(token)
            .cloned()
            .ok_or_else(|| ServiceError::Unauthenticated("unknown bearer token".into()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bad_token_entries_name_the_entry_the_rule_and_what_was_there() {
        let t = Tenants::load("lab:abcdefgh, other:12345678", None).unwrap();
        assert!(!t.is_open());
        let e = Tenants::load("lab:abcdefgh,nocolon", None).unwrap_err();
        assert_eq!(e.field, "--tokens entry 1");
        assert!(
            e.limit.contains("tenant:token") && e.value.contains("7 characters"),
            "{e}"
        );
        let e = Tenants::load("lab:short", None).unwrap_err();
        assert!(
            e.limit.contains("at least 8") && e.value.contains("5 characters"),
            "{e}"
        );
        assert!(
            !e.to_string().contains("short"),
            "tokens are not echoed: {e}"
        );
        let e = Tenants::load("a:abcdefgh,b:abcdefgh", None).unwrap_err();
        assert_eq!(
            (e.field.as_str(), e.value.as_str()),
            ("--tokens entry 1", "a duplicate token")
        );
        let dir = tempfile::tempdir().unwrap();
        let f = dir.path().join("tokens.txt");
        std::fs::write(&f, "# lab tokens\nlab abcdefgh\nbroken line here\n").unwrap();
        let e = Tenants::load("", Some(&f)).unwrap_err();
        assert!(e.field.ends_with("line 3") && e.value == "3 fields", "{e}");
        let e = Tenants::load("", Some(&dir.path().join("missing"))).unwrap_err();
        assert_eq!(e.field, "--tokens-file");
    }
}
