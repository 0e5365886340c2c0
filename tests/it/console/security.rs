//! Issue #25: who may use the console — the real binary on real sockets (Host, Origin, the secret,
//! connection and message limits).

use super::*;
use util::live::runtime;

fn url_parts(url: &str) -> (String, String) {
    let rest = url.strip_prefix("http://").expect("an http URL");
    let (authority, query) = rest.split_once("/?token=").expect("a URL with the secret");
    (authority.to_string(), query.to_string())
}

/// One raw HTTP request with exactly these headers; the status code and the whole answer.
fn raw_get(addr: SocketAddr, target: &str, headers: &[(&str, String)]) -> (u16, String) {
    use std::io::{Read, Write};
    let mut stream = std::net::TcpStream::connect(addr).unwrap();
    let mut request = format!("GET {target} HTTP/1.1\r\nConnection: close\r\n");
    for (name, value) in headers {
        request.push_str(&format!("{name}: {value}\r\n"));
    }
    request.push_str("\r\n");
    stream.write_all(request.as_bytes()).unwrap();
    let mut text = String::new();
    let _ = stream.read_to_string(&mut text);
    let status = text
        .split(' ')
        .nth(1)
        .and_then(|code| code.parse().ok())
        .unwrap_or_else(|| panic!("no HTTP status in {text:?}"));
    (status, text)
}

/// A WebSocket upgrade to `ws://addr/ws?query` with exactly these Host and Origin headers (none
/// when `None`): `Ok` with the socket when the console accepts it, else the refusal's status.
async fn upgrade(
    addr: SocketAddr,
    query: &str,
    host: Option<&str>,
    origin: Option<&str>,
) -> Result<util::live::Socket, u16> {
    use tokio_tungstenite::tungstenite::client::IntoClientRequest;
    let mut request = format!("ws://{addr}/ws?{query}")
        .into_client_request()
        .unwrap();
    let headers = request.headers_mut();
    headers.remove("Host");
    if let Some(host) = host {
        headers.insert("Host", host.parse().unwrap());
    }
    if let Some(origin) = origin {
        headers.insert("Origin", origin.parse().unwrap());
    }
    let stream = tokio::net::TcpStream::connect(addr).await.unwrap();
    let stream = tokio_tungstenite::MaybeTlsStream::Plain(stream);
    match tokio_tungstenite::client_async(request, stream).await {
        Ok((socket, _)) => Ok(socket),
        Err(tokio_tungstenite::tungstenite::Error::Http(response)) => {
            Err(response.status().as_u16())
        }
        Err(e) => panic!("the upgrade failed otherwise: {e}"),
    }
}

/// Every command the page can send.
const COMMANDS: [&str; 8] = [
    r#"{"cmd":"stop"}"#,
    r#"{"cmd":"confirm"}"#,
    r#"{"cmd":"decline"}"#,
    r#"{"cmd":"capture"}"#,
    r#"{"cmd":"freedrive","on":true}"#,
    r#"{"cmd":"freedrive","on":false}"#,
    r#"{"cmd":"go_to_suggestion"}"#,
    r#"{"cmd":"finish"}"#,
];

/// The events a page gets until the console closes (the history first).
async fn events_until_closed(socket: &mut util::live::Socket) -> Vec<serde_json::Value> {
    use futures_util::StreamExt;
    let mut events = Vec::new();
    while let Ok(Some(Ok(message))) = tokio::time::timeout(util::live::STEP, socket.next()).await {
        if let tokio_tungstenite::tungstenite::Message::Text(text) = message {
            events.push(serde_json::from_str(&text).unwrap());
        }
    }
    events
}

#[test]
fn foreign_pages_rebound_hosts_and_missing_or_wrong_secrets_are_refused_for_every_command() {
    use futures_util::SinkExt;
    let dir = tempfile::tempdir().unwrap();
    let config = sim_config(dir.path(), 20, 0.0);
    let session = dir.path().join("session");
    // A hand-guided session: its page's commands move the arm and finish the session.
    let mut live = util::live::Live::console(&config, &session, dir.path());
    let url = live.url();
    let (authority, secret) = url_parts(&url);
    let addr: SocketAddr = authority.parse().unwrap();
    let own = format!("http://{authority}");
    let rebound = format!("attacker.example:{}", addr.port());
    let with_secret = format!("token={secret}");
    let wrong = format!("token={}", "0".repeat(32));
    // (what it is, Host, Origin, query)
    let cases: Vec<(&str, Option<String>, Option<String>, String)> = vec![
        (
            "a page of another site",
            Some(authority.clone()),
            Some("http://evil.example".into()),
            with_secret.clone(),
        ),
        (
            "a sandboxed page (Origin null)",
            Some(authority.clone()),
            Some("null".into()),
            with_secret.clone(),
        ),
        (
            "a file:// page",
            Some(authority.clone()),
            Some("file://".into()),
            with_secret.clone(),
        ),
        (
            "no Origin",
            Some(authority.clone()),
            None,
            with_secret.clone(),
        ),
        (
            "DNS rebinding (Host and Origin of the attacker's name)",
            Some(rebound.clone()),
            Some(format!("http://{rebound}")),
            with_secret.clone(),
        ),
        (
            "no secret",
            Some(authority.clone()),
            Some(own.clone()),
            String::new(),
        ),
        (
            "a wrong secret",
            Some(authority.clone()),
            Some(own.clone()),
            wrong.clone(),
        ),
    ];
    let rt = runtime();
    let mut refused = 0;
    for (what, host, origin, query) in &cases {
        for command in COMMANDS {
            let answer = rt.block_on(upgrade(addr, query, host.as_deref(), origin.as_deref()));
            match answer {
                Err(status) => {
                    assert!(
                        status == 401 || status == 403,
                        "{what}: refused with {status}, not 401/403"
                    );
                    refused += 1;
                }
                Ok(mut socket) => {
                    let _ = rt.block_on(socket.send(command.into()));
                    panic!("{what}: the WebSocket was accepted (and {command} sent)");
                }
            }
        }
    }
    assert_eq!(refused, cases.len() * COMMANDS.len());
    // The page and the report: a rebound Host, none, no secret, a wrong one, a foreign fetch.
    for (what, target, headers) in [
        (
            "a rebound Host",
            format!("/?{with_secret}"),
            vec![("Host", rebound.clone())],
        ),
        ("no Host", format!("/?{with_secret}"), vec![]),
        (
            "no secret",
            "/".to_string(),
            vec![("Host", authority.clone())],
        ),
        (
            "a wrong secret",
            format!("/?{wrong}"),
            vec![("Host", authority.clone())],
        ),
        (
            "a fetch from another site",
            format!("/?{with_secret}"),
            vec![
                ("Host", authority.clone()),
                ("Origin", "http://evil.example".to_string()),
            ],
        ),
        (
            "the report without the secret",
            "/report".to_string(),
            vec![("Host", authority.clone())],
        ),
    ] {
        let (status, text) = raw_get(addr, &target, &headers);
        // (400: an HTTP/1.1 request without Host may be refused before the gate sees it.)
        assert!(
            matches!(status, 400 | 401 | 403),
            "{what}: {status}\n{text}"
        );
        assert!(
            !text.contains("<title>handeye console</title>"),
            "{what}: the page was served"
        );
    }
    // An absolute-form target naming another host, the Host header local (#40: it was served).
    let (status, text) = raw_get(
        addr,
        &format!("http://evil.example:{}/?{with_secret}", addr.port()),
        &[("Host", authority.clone())],
    );
    assert!(
        matches!(status, 400 | 403) && !text.contains("<title>handeye console</title>"),
        "an absolute-form target naming another host: {status}\n{text}"
    );
    let (status, text) = raw_get(addr, "/", &[("Host", authority.clone())]);
    assert!(
        text.contains("open the URL the terminal printed"),
        "a page without the secret is told where to find it ({status}):\n{text}"
    );
    // Nothing moved, nothing ended: the session runs on with no capture.
    assert!(live.running(), "a refused page ended the session");

    // The legitimate page (the printed URL) still works: it sees no capture, and its STOP ends
    // the session with the samples (none) kept.
    let (status, page) = raw_get(
        addr,
        &format!("/?{with_secret}"),
        &[("Host", authority.clone())],
    );
    assert_eq!(status, 200);
    assert!(page.contains("<title>handeye console</title>") && page.contains("no-referrer"));
    let events = rt.block_on(async {
        let (mut socket, _) = tokio_tungstenite::connect_async(util::console_socket(&url))
            .await
            .expect("the page's own socket is accepted");
        socket.send(r#"{"cmd":"stop"}"#.into()).await.unwrap();
        events_until_closed(&mut socket).await
    });
    assert!(
        !events
            .iter()
            .any(|e| e["type"] == "check" || e["state"] == "captured"),
        "a refused command moved the arm or captured: {events:#?}"
    );
    let (ok, out) = live.finish();
    assert!(
        !ok && out.contains("interrupted"),
        "STOP from the page:\n{out}"
    );
    // Refusals are logged, the first few only.
    let logged = out
        .lines()
        .filter(|l| l.contains("console: refused"))
        .count();
    assert!(
        (1..=5).contains(&logged),
        "{logged} refusal lines for {} refusals:\n{out}",
        refused + 6
    );
}

#[test]
fn a_public_console_needs_the_secret_too_and_says_so() {
    use futures_util::SinkExt;
    let dir = tempfile::tempdir().unwrap();
    let config = sim_config(dir.path(), 20, 0.0);
    let (config_s, out_s) = (
        config.display().to_string(),
        dir.path().join("session").display().to_string(),
    );
    let mut live = util::live::Live::start(
        &[
            "console",
            "--config",
            &config_s,
            "--output",
            &out_s,
            "--addr",
            "0.0.0.0:0",
            "--public",
        ],
        dir.path(),
    );
    let url = live.url();
    let (authority, secret) = url_parts(&url);
    let port: u16 = authority.rsplit_once(':').unwrap().1.parse().unwrap();
    let addr = SocketAddr::from(([127, 0, 0, 1], port));
    // Reached by a name of the lab's network: any name, but never without the secret.
    let host = format!("cell-pc.lab:{port}");
    let origin = format!("http://{host}");
    let (status, _) = raw_get(addr, "/", &[("Host", host.clone())]);
    assert_eq!(status, 401, "the public page without the secret");
    let rt = runtime();
    for query in [String::new(), format!("token={}", "f".repeat(32))] {
        let refused = rt.block_on(upgrade(addr, &query, Some(&host), Some(&origin)));
        assert!(
            matches!(refused, Err(401 | 403)),
            "a public WebSocket with {query:?}: {:?}",
            refused.map(|_| "accepted")
        );
    }
    assert!(live.running());
    let (status, _) = raw_get(
        addr,
        &format!("/?token={secret}"),
        &[("Host", host.clone())],
    );
    assert_eq!(status, 200, "the public page with the secret");
    rt.block_on(async {
        let mut socket = upgrade(addr, &format!("token={secret}"), Some(&host), Some(&origin))
            .await
            .unwrap_or_else(|status| panic!("the public page with its secret: {status}"));
        socket.send(r#"{"cmd":"stop"}"#.into()).await.unwrap();
        events_until_closed(&mut socket).await;
    });
    let (ok, out) = live.finish();
    assert!(!ok && out.contains("interrupted"), "STOP:\n{out}");
    assert!(
        out.contains("WARNING: the console serves on") && out.contains("secret"),
        "the start says the public console needs its secret:\n{out}"
    );
}

/// `handeye run` of the sim cell (`count` poses, moves of `move_duration_s`) in `dir` with its
/// console on a free local port.
fn run_with_console(dir: &Path, count: usize, move_duration_s: f64) -> util::live::Live {
    let config = sim_config(dir, count, move_duration_s);
    let out = dir.join("session");
    let (config_s, out_s) = (config.display().to_string(), out.display().to_string());
    util::live::Live::start(
        &[
            "run",
            "--config",
            &config_s,
            "--output",
            &out_s,
            "--console",
            "127.0.0.1:0",
        ],
        dir,
    )
}

/// Raises this process's own descriptor limit (the attacker's side of the flood test) as far
/// as its hard limit allows, up to `want`.
fn raise_nofile(want: u64) {
    use rustix::process::{getrlimit, setrlimit, Resource, Rlimit};
    let limit = getrlimit(Resource::Nofile);
    // `None` is unlimited.
    if limit.current.is_some_and(|current| current < want) {
        let raised = Rlimit {
            current: Some(limit.maximum.map_or(want, |max| want.min(max))),
            maximum: limit.maximum,
        };
        let _ = setrlimit(Resource::Nofile, raised);
    }
}

#[test]
fn two_thousand_connections_under_ulimit_1024_leave_the_run_good() {
    use std::io::Write;
    use std::sync::atomic::AtomicUsize;
    use std::sync::Mutex;
    raise_nofile(8192);
    let dir = tempfile::tempdir().unwrap();
    // Slow moves: the run is still going while the flood comes.
    let config = sim_config(dir.path(), 12, 1.2);
    let out = dir.path().join("session");
    let mut live = util::live::Live::spawn(
        Command::new("bash")
            .arg("-c")
            .arg(r#"ulimit -n 1024 && exec "$0" "$@""#)
            .arg(env!("CARGO_BIN_EXE_handeye"))
            .args(["run", "--config"])
            .arg(&config)
            .arg("--output")
            .arg(&out)
            .args(["--console", "127.0.0.1:0"])
            .current_dir(dir.path()),
    );
    let url = live.url();
    let (authority, secret) = url_parts(&url);
    let addr: SocketAddr = authority.parse().unwrap();
    const ATTEMPTS: usize = 2000;
    let attempts = Arc::new(AtomicUsize::new(0));
    let held = Arc::new(Mutex::new(Vec::new()));
    let threads: Vec<_> = (0..32)
        .map(|_| {
            let (attempts, held, authority, secret) =
                (attempts.clone(), held.clone(), authority.clone(), secret.clone());
            std::thread::spawn(move || loop {
                let n = attempts.fetch_add(1, Ordering::SeqCst);
                if n >= ATTEMPTS {
                    attempts.fetch_sub(1, Ordering::SeqCst);
                    return;
                }
                // Beyond the console's cap, connections wait in the kernel's queue and then
                // time out: that is the point.
                let Ok(mut stream) =
                    std::net::TcpStream::connect_timeout(&addr, Duration::from_millis(50))
                else {
                    continue;
                };
                // Three kinds, held open: a request whose headers never end, an authenticated
                // page that never reads, and a connection that says nothing.
                let _ = match n % 3 {
                    0 => write!(stream, "GET /?token={secret} HTTP/1.1\r\nHost: {authority}\r\n"),
                    1 => write!(
                        stream,
                        "GET /ws?token={secret} HTTP/1.1\r\nHost: {authority}\r\nOrigin: http://{authority}\r\nUpgrade: websocket\r\nConnection: Upgrade\r\nSec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n\r\n"
                    ),
                    _ => Ok(()),
                };
                held.lock().unwrap().push(stream);
            })
        })
        .collect();
    for thread in threads {
        thread.join().unwrap();
    }
    let running_after_flood = live.running();
    let connected = held.lock().unwrap().len();
    let (ok, text) = live.finish();
    drop(held);
    assert_eq!(attempts.load(Ordering::SeqCst), ATTEMPTS);
    assert!(
        running_after_flood,
        "the run ended before the {ATTEMPTS} attempts were made (the test proves nothing):\n{text}"
    );
    assert!(
        ok,
        "the run failed under the flood ({connected} connected):\n{text}"
    );
    assert!(
        text.contains("GOOD"),
        "the run under the flood is not GOOD:\n{text}"
    );
    assert!(
        !text.contains("Too many open files"),
        "the run ran out of descriptors:\n{text}"
    );
}

#[test]
fn an_oversized_message_or_a_stream_of_junk_drops_the_page_and_is_logged_once_shortened() {
    use futures_util::{SinkExt, StreamExt};
    use tokio_tungstenite::tungstenite::Message;
    let dir = tempfile::tempdir().unwrap();
    let mut live = run_with_console(dir.path(), 8, 1.0);
    let url = live.url();
    let rt = runtime();
    rt.block_on(async {
        // 64 MiB in one message: the page is dropped as soon as the frame's length is read.
        let (mut socket, _) = tokio_tungstenite::connect_async(util::console_socket(&url))
            .await
            .unwrap();
        let huge = "x".repeat(64 << 20);
        let _ = socket.send(Message::Text(huge.into())).await;
        let closed = tokio::time::timeout(Duration::from_secs(30), async {
            while let Some(Ok(_)) = socket.next().await {}
        })
        .await;
        assert!(closed.is_ok(), "the page that sent 64 MiB was not dropped");

        // Junk of 3 kB, again and again: logged once, shortened, and the page dropped.
        let (mut socket, _) = tokio_tungstenite::connect_async(util::console_socket(&url))
            .await
            .unwrap();
        let junk = format!(r#"{{"cmd":"{}"}}"#, "j".repeat(3000));
        for _ in 0..40 {
            if socket
                .send(Message::Text(junk.clone().into()))
                .await
                .is_err()
            {
                break;
            }
        }
        let closed = tokio::time::timeout(Duration::from_secs(30), async {
            while let Some(Ok(_)) = socket.next().await {}
        })
        .await;
        assert!(closed.is_ok(), "the page sending junk was not dropped");
    });
    let (ok, text) = live.finish();
    assert!(
        ok && text.contains("GOOD"),
        "the run goes on to GOOD:\n{text}"
    );
    let junk_lines: Vec<&str> = text.lines().filter(|l| l.contains("no command")).collect();
    assert_eq!(
        junk_lines.len(),
        2,
        "the junk is logged once, and the page's drop once: {junk_lines:#?}"
    );
    assert!(
        text.len() < 64 * 1024,
        "the run's output holds what the pages sent ({} bytes)",
        text.len()
    );
}

/// A run with its console, `count` connections pipelining 600 page loads each (with the secret
/// or without it) and never reading an answer (about 11 MB of answers each, far beyond the
/// socket buffers, which the attacker keeps small), held open; then the operator's page load
/// with the secret, 2 s later (the stalled connections have filled their answers' buffers and
/// blocked the console's writes by then), checked to be the page while the run still runs.
struct Behind {
    live: util::live::Live,
    url: String,
    stalled: Vec<std::net::TcpStream>,
    started: std::time::Instant,
    /// The page load's status, and how long it took.
    status: u16,
    loaded: Duration,
}

fn page_behind_stalled_connections(dir: &Path, count: usize, with_secret: bool) -> Behind {
    raise_nofile(4096);
    // Slow moves: the run goes on through the whole test.
    let mut live = run_with_console(dir, 12, 2.5);
    let url = live.url();
    let (authority, secret) = url_parts(&url);
    let addr: SocketAddr = authority.parse().unwrap();
    let target = if with_secret {
        format!("/?token={secret}")
    } else {
        "/".to_string()
    };
    let request = format!("GET {target} HTTP/1.1\r\nHost: {authority}\r\n\r\n").repeat(600);
    let stalled = stalled_connections(addr, &request, count);
    std::thread::sleep(Duration::from_secs(2));
    let started = std::time::Instant::now();
    let (status, text) = raw_get(addr, &format!("/?token={secret}"), &[("Host", authority)]);
    let loaded = started.elapsed();
    assert_eq!(status, 200, "{text}");
    assert!(text.contains("<html"), "not the page: {text}");
    assert!(
        live.running(),
        "the run ended before the page was asked for (the test proves nothing)"
    );
    Behind {
        live,
        url,
        stalled,
        started,
        status,
        loaded,
    }
}

/// #40: more connections than the console has slots, each pipelining hundreds of page loads
/// with the secret and never reading an answer, held open: a page load still gets its page (a
/// blocked write has a deadline, so the stalled connections give their slots back), and the run
/// ends GOOD. Before the deadline, four tries over 80 s got nothing.
#[test]
fn connections_that_never_read_their_answers_do_not_keep_a_page_out() {
    let dir = tempfile::tempdir().unwrap();
    let behind = page_behind_stalled_connections(dir.path(), 72, true);
    eprintln!(
        "a page load behind 72 stalled connections: {} after {:.1?}",
        behind.status, behind.loaded
    );
    drop(behind.stalled);
    let (ok, out) = behind.live.finish();
    assert!(
        ok && out.contains("GOOD"),
        "the run under stalled connections:\n{out}"
    );
}

/// #40, the issue's case: 200 connections from someone without the console's secret, each
/// pipelining page loads and never reading an answer, held open: the operator's page (with the
/// secret) loads and its STOP stops the run, both within 5 s of asking, and the samples are kept
/// for resume. (Someone who has the secret can press STOP himself; a slot that a request with
/// the secret holds is given back by the write deadline: the test above.)
#[test]
fn two_hundred_slow_readers_without_the_secret_do_not_keep_the_operators_stop_out() {
    let dir = tempfile::tempdir().unwrap();
    let behind = page_behind_stalled_connections(dir.path(), 200, false);
    runtime().block_on(async {
        let mut page = util::live::Page::open(&behind.url).await;
        page.send("stop").await;
    });
    let sent = behind.started.elapsed();
    eprintln!(
        "behind 200 slow readers without the secret: the page in {:.1?}, its STOP sent after {sent:.1?}",
        behind.loaded
    );
    assert!(
        sent < Duration::from_secs(5),
        "the page and its STOP took {sent:.1?}"
    );
    let (ok, out) = behind.live.finish();
    drop(behind.stalled);
    assert!(!ok, "the run went on after STOP:\n{out}");
    assert!(
        out.contains("--resume"),
        "the stop says how to resume:\n{out}"
    );
}

/// `count` connections to `addr`, each sending `request` (pipelined requests) with a small
/// receive buffer and never reading an answer; held open while the returned streams live.
fn stalled_connections(addr: SocketAddr, request: &str, count: usize) -> Vec<std::net::TcpStream> {
    use std::io::Write;
    runtime().block_on(async {
        let mut stalled = Vec::new();
        for _ in 0..count {
            let socket = tokio::net::TcpSocket::new_v4().unwrap();
            socket.set_recv_buffer_size(4096).unwrap();
            let stream = socket.connect(addr).await.unwrap().into_std().unwrap();
            stream.set_nonblocking(false).unwrap();
            let mut writer = &stream;
            writer.write_all(request.as_bytes()).unwrap();
            stalled.push(stream);
        }
        stalled
    })
}
