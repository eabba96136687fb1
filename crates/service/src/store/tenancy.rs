//! Tenants: every scene and job belongs to one, and a caller sees only its own tenant's unless
//! it is an admin. The store's reads and writes by id take the [`Caller`] and filter in SQL, so
//! REST and gRPC handlers cannot forget the check; another tenant's resource looks exactly like
//! a missing one (404), so ids do not leak.

/// The tenant of plain `auth.tokens`, of everything when authentication is off, and of rows
/// written before tenants existed.
pub const DEFAULT_TENANT: &str = "default";

/// Who is asking: the tenant that owns what it creates, and whether it sees every tenant's.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Caller {
    pub tenant: String,
    pub admin: bool,
}

impl Caller {
    pub fn tenant(tenant: impl Into<String>) -> Self {
        Self {
            tenant: tenant.into(),
            admin: false,
        }
    }

    pub fn admin(tenant: impl Into<String>) -> Self {
        Self {
            tenant: tenant.into(),
            admin: true,
        }
    }

    /// The service itself (workers, sweeps, the local CLI) and every caller while
    /// authentication is off: sees everything, creates in the default tenant.
    pub fn system() -> Self {
        Self::admin(DEFAULT_TENANT)
    }

    /// Whether this caller may see and touch what `owner` owns.
    pub fn sees(&self, owner: &str) -> bool {
        self.admin || self.tenant == owner
    }
}

/// The SQL condition that keeps rows of `column` this caller sees; bind
/// [`Caller::admin`] then [`Caller::tenant`] for its two placeholders.
pub(super) fn visible(column: &str) -> String {
    format!("(? OR {column} = ?)")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tenants_see_their_own_and_admins_everything() {
        let alpha = Caller::tenant("alpha");
        assert!(alpha.sees("alpha"));
        assert!(!alpha.sees("beta"));
        assert!(Caller::admin("ops").sees("beta"));
        assert!(Caller::system().sees("anything"));
        assert_eq!(visible("tenant"), "(? OR tenant = ?)");
    }
}
