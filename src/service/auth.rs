//! Tenants: bearer tokens → tenant names, shared by REST and gRPC.
//!
//! Why it exists: a lab shares one server; each client sees only its own jobs (another
//! tenant's job id answers 404, never 403, so ids leak nothing). Tokens come from
//! `--tokens tenant:token,...` (env `PHYSNAP_TOKENS`) or a file with one `tenant token` pair a
//! line. With no tokens configured every request is the tenant `local`; `serve` allows that
//! only when every public listener is on a loopback address.

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
    /// lines (`#` comments). Errors name the entry.
    pub fn load(inline: &str, file: Option<&Path>) -> Result<Tenants, String> {
        let mut t = Tenants::default();
        for (i, pair) in inline
            .split(',')
            .map(str::trim)
            .filter(|p| !p.is_empty())
            .enumerate()
        {
            let (tenant, token) = pair
                .split_once(':')
                .ok_or_else(|| format!("--tokens entry {i}: expected tenant:token"))?;
            t.add(tenant.trim(), token.trim(), &format!("--tokens entry {i}"))?;
        }
        if let Some(path) = file {
            let text = std::fs::read_to_string(path)
                .map_err(|e| format!("--tokens-file {}: {e}", path.display()))?;
            for (n, line) in text.lines().enumerate() {
                let line = line.trim();
                if line.is_empty() || line.starts_with('#') {
                    continue;
                }
                let mut it = line.split_whitespace();
                let (Some(tenant), Some(token), None) = (it.next(), it.next(), it.next()) else {
                    return Err(format!(
                        "--tokens-file {} line {}: expected `tenant token`",
                        path.display(),
                        n + 1
                    ));
                };
                t.add(tenant, token, &format!("{} line {}", path.display(), n + 1))?;
            }
        }
        Ok(t)
    }

    fn add(&mut self, tenant: &str, token: &str, at: &str) -> Result<(), String> {
        if tenant.is_empty() || token.len() < 8 {
            return Err(format!(
                "{at}: tenant must be non-empty and the token at least 8 characters"
            ));
        }
        if self
            .by_token
            .insert(token.to_string(), tenant.to_string())
            .is_some()
        {
            return Err(format!("{at}: duplicate token"));
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
