//! Who may use the console. Any web page the user has open can make the browser connect to
//! `ws://127.0.0.1:PORT` (WebSockets are not bound by the same-origin policy) and any page can
//! point a name of its own at this machine (DNS rebinding), so three checks guard every request:
//!
//! - **Host** must name this console: on a loopback console, a loopback address or `localhost`
//!   with the console's port (a rebound name like `attacker.example:8765` is refused); on a
//!   public one, any name with the console's port (the secret is what guards it there).
//! - **Origin**, when the request carries one, must be the console's own page
//!   (`http://` + the Host); the WebSocket must carry one (every browser sends it on an
//!   upgrade), so a page of another site, a `file://` page or a sandboxed (`null`) one is refused.
//! - **The secret**: a random token made for each console start, printed in its URL
//!   (`/?token=…`, as Jupyter does); the page keeps it and passes it on the WebSocket and the
//!   report link. Compared in constant time.
//!
//! Commands only ever arrive on a WebSocket that passed all three, so STOP, capture, freedrive,
//! go-to-suggestion, confirm and finish are accepted only from the authenticated page.

use std::fmt;
use std::net::{IpAddr, SocketAddr};

use rand::Rng;
use subtle::ConstantTimeEq;

/// The query parameter that carries the secret.
pub(super) const TOKEN_PARAM: &str = "token";

/// The checks of one console: its address and its secret.
pub(super) struct Gate {
    listen: SocketAddr,
    public: bool,
    token: String,
}

/// Why a request was refused (the text goes back to the client and, shortened, to the log).
#[derive(Debug, Clone, PartialEq, Eq)]
pub(super) enum Refusal {
    /// No Host header, or one that does not name this console.
    Host(Option<String>),
    /// An Origin other than the console's own page.
    Origin(String),
    /// A WebSocket upgrade without an Origin (no browser page makes one).
    NoOrigin,
    /// No secret in the request.
    NoToken,
    /// A secret, but not this console's.
    WrongToken,
}

impl Refusal {
    /// The HTTP status the refusal answers with.
    pub(super) fn status(&self) -> axum::http::StatusCode {
        match self {
            Refusal::NoToken => axum::http::StatusCode::UNAUTHORIZED,
            _ => axum::http::StatusCode::FORBIDDEN,
        }
    }
}

/// At most this much of what a client sent (a header, a message) goes into a log line.
const SHOWN: usize = 80;

pub(super) fn shortened(text: &str) -> String {
    if text.chars().count() <= SHOWN {
        format!("{text:?}")
    } else {
        let head: String = text.chars().take(SHOWN).collect();
        format!("{head:?}… ({} bytes)", text.len())
    }
}

impl fmt::Display for Refusal {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Refusal::Host(None) => write!(f, "refused: the request names no Host"),
            Refusal::Host(Some(host)) => write!(
                f,
                "refused: Host {} is not this console's address (a page of another site pointing its name here?)",
                shortened(host)
            ),
            Refusal::Origin(origin) => write!(
                f,
                "refused: a page of {} is not this console's page",
                shortened(origin)
            ),
            Refusal::NoOrigin => write!(
                f,
                "refused: a WebSocket without an Origin (only the console's own page may connect)"
            ),
            Refusal::NoToken => write!(
                f,
                "refused: this console needs its secret; open the URL the terminal printed (http://…/?token=…)"
            ),
            Refusal::WrongToken => write!(
                f,
                "refused: wrong secret; open the URL the terminal printed for this run (the secret is new each time the console starts)"
            ),
        }
    }
}

impl Gate {
    /// A gate with a new random secret (128 bits from the thread's CSPRNG, seeded by the OS).
    pub(super) fn new(listen: SocketAddr, public: bool) -> Gate {
        let bytes: [u8; 16] = rand::rng().random();
        let token = bytes.iter().map(|b| format!("{b:02x}")).collect();
        Gate {
            listen,
            public,
            token,
        }
    }

    /// The secret.
    pub(super) fn token(&self) -> &str {
        &self.token
    }

    /// Checks one request: its Host, its Origin (required when `upgrade`), and the secret in its
    /// query string.
    pub(super) fn check(
        &self,
        host: Option<&str>,
        origin: Option<&str>,
        query: Option<&str>,
        upgrade: bool,
    ) -> Result<(), Refusal> {
        let host = host.ok_or(Refusal::Host(None))?;
        if !self.host_allowed(host) {
            return Err(Refusal::Host(Some(host.to_string())));
        }
        match origin {
            Some(origin) => {
                // Same origin: the scheme is http (the console serves no TLS) and the authority
                // is the Host just checked.
                let own = format!("http://{host}");
                if !origin.eq_ignore_ascii_case(&own) {
                    return Err(Refusal::Origin(origin.to_string()));
                }
            }
            None if upgrade => return Err(Refusal::NoOrigin),
            None => {}
        }
        let given = query
            .into_iter()
            .flat_map(|q| q.split('&'))
            .find_map(|pair| pair.strip_prefix(TOKEN_PARAM)?.strip_prefix('='))
            .ok_or(Refusal::NoToken)?;
        if bool::from(given.as_bytes().ct_eq(self.token.as_bytes())) {
            Ok(())
        } else {
            Err(Refusal::WrongToken)
        }
    }

    /// Whether `host` (a Host header: `name[:port]`) names this console.
    fn host_allowed(&self, host: &str) -> bool {
        let Some((name, port)) = split_host(host) else {
            return false;
        };
        if port != self.listen.port() {
            return false;
        }
        if self.public {
            return !name.is_empty();
        }
        if name.eq_ignore_ascii_case("localhost") {
            return true;
        }
        match name.parse::<IpAddr>() {
            Ok(ip) => ip.is_loopback(),
            Err(_) => false,
        }
    }
}

/// `name[:port]` or `[v6][:port]` → (name without brackets, port; 80 when absent).
fn split_host(host: &str) -> Option<(&str, u16)> {
    if let Some(rest) = host.strip_prefix('[') {
        let (name, after) = rest.split_once(']')?;
        let port = match after {
            "" => 80,
            _ => after.strip_prefix(':')?.parse().ok()?,
        };
        return Some((name, port));
    }
    match host.rsplit_once(':') {
        Some((name, port)) => Some((name, port.parse().ok()?)),
        None => Some((host, 80)),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn local() -> Gate {
        Gate::new("127.0.0.1:8765".parse().unwrap(), false)
    }

    fn query(gate: &Gate) -> String {
        format!("token={}", gate.token())
    }

    #[test]
    fn the_page_of_this_console_passes() {
        let gate = local();
        let q = query(&gate);
        for host in [
            "127.0.0.1:8765",
            "localhost:8765",
            "LOCALHOST:8765",
            "[::1]:8765",
        ] {
            let origin = format!("http://{host}");
            assert_eq!(
                gate.check(Some(host), Some(&origin), Some(&q), true),
                Ok(())
            );
            // A navigation carries no Origin.
            assert_eq!(gate.check(Some(host), None, Some(&q), false), Ok(()));
        }
        // The token among other parameters.
        let q = format!("a=1&{}&b=2", query(&gate));
        assert_eq!(
            gate.check(Some("127.0.0.1:8765"), None, Some(&q), false),
            Ok(())
        );
    }

    #[test]
    fn foreign_hosts_origins_and_secrets_are_refused() {
        let gate = local();
        let q = query(&gate);
        let host = "127.0.0.1:8765";
        // DNS rebinding: a name of the attacker's pointing here.
        assert!(matches!(
            gate.check(Some("attacker.example:8765"), None, Some(&q), false),
            Err(Refusal::Host(_))
        ));
        assert!(matches!(
            gate.check(Some("127.0.0.1:9999"), None, Some(&q), false),
            Err(Refusal::Host(_))
        ));
        assert_eq!(
            gate.check(None, None, Some(&q), false),
            Err(Refusal::Host(None))
        );
        for origin in [
            "http://evil.example",
            "null",
            "file://",
            "https://127.0.0.1:8765",
            "http://127.0.0.1:8765.evil.example",
        ] {
            assert_eq!(
                gate.check(Some(host), Some(origin), Some(&q), true),
                Err(Refusal::Origin(origin.into())),
                "{origin}"
            );
        }
        assert_eq!(
            gate.check(Some(host), None, Some(&q), true),
            Err(Refusal::NoOrigin)
        );
        let origin = format!("http://{host}");
        assert_eq!(
            gate.check(Some(host), Some(&origin), None, true),
            Err(Refusal::NoToken)
        );
        assert_eq!(
            gate.check(Some(host), Some(&origin), Some("token="), true),
            Err(Refusal::WrongToken)
        );
        let almost = format!("token={}0", gate.token());
        assert_eq!(
            gate.check(Some(host), Some(&origin), Some(&almost), true),
            Err(Refusal::WrongToken)
        );
        // Another console's secret.
        let other = format!("token={}", local().token());
        assert_eq!(
            gate.check(Some(host), Some(&origin), Some(&other), true),
            Err(Refusal::WrongToken)
        );
    }

    #[test]
    fn a_public_console_takes_any_name_but_still_needs_the_secret() {
        let gate = Gate::new("0.0.0.0:8765".parse().unwrap(), true);
        let q = query(&gate);
        assert_eq!(
            gate.check(Some("cell-pc.lab:8765"), None, Some(&q), false),
            Ok(())
        );
        assert_eq!(
            gate.check(
                Some("cell-pc.lab:8765"),
                Some("http://cell-pc.lab:8765"),
                Some(&q),
                true
            ),
            Ok(())
        );
        assert_eq!(
            gate.check(Some("cell-pc.lab:8765"), None, None, false),
            Err(Refusal::NoToken)
        );
        assert!(gate
            .check(
                Some("cell-pc.lab:8765"),
                Some("http://evil.example"),
                Some(&q),
                true
            )
            .is_err());
    }

    #[test]
    fn secrets_differ_between_starts_and_are_128_bits() {
        let (a, b) = (local(), local());
        assert_ne!(a.token(), b.token());
        assert_eq!(a.token().len(), 32);
        assert!(a.token().chars().all(|c| c.is_ascii_hexdigit()));
    }

    #[test]
    fn long_headers_are_shortened_in_messages() {
        let text = Refusal::Origin("x".repeat(100_000)).to_string();
        assert!(text.len() < 200, "{}", text.len());
    }
}
