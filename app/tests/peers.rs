//! End to end with real processes on loopback: a discovery node and `sculpt peer` processes
//! with their own stores converge to one scene hash; a peer killed with SIGKILL mid-sync
//! restarts from its store and converges again; a peer that edited offline syncs its edits
//! when it next meets the others; a second process on a store is refused, naming the first;
//! a peer with another session's invite is refused with a message a person can act on.
#![allow(
    clippy::unwrap_used,
    reason = "helpers outside #[test] fns unwrap process plumbing"
)]

use std::io::{BufRead as _, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::mpsc::{Receiver, channel};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use serde_json::Value;

/// Longest wait for any one condition.
const WAIT: Duration = Duration::from_secs(60);

fn scratch(name: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join(name);
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn sculpt() -> Command {
    let mut command = Command::new(env!("CARGO_BIN_EXE_sculpt"));
    command.env("RUST_BACKTRACE", "1");
    command
}

/// A running `sculpt` process whose stdout lines and stderr are collected by threads.
struct Proc {
    name: String,
    child: Child,
    lines: Receiver<String>,
    stderr: Arc<Mutex<String>>,
    last: Option<Value>,
}

impl Proc {
    fn spawn(name: &str, mut command: Command) -> Proc {
        let mut child = command
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        let (tx, lines) = channel();
        let stdout = child.stdout.take().unwrap();
        std::thread::Builder::new()
            .name("sculpt-test-pipe".into())
            .spawn(move || {
                for line in BufReader::new(stdout).lines() {
                    let Ok(line) = line else { break };
                    if tx.send(line).is_err() {
                        break;
                    }
                }
            })
            .unwrap();
        let stderr = Arc::new(Mutex::new(String::new()));
        let sink = stderr.clone();
        let pipe = child.stderr.take().unwrap();
        std::thread::Builder::new()
            .name("sculpt-test-pipe".into())
            .spawn(move || {
                for line in BufReader::new(pipe).lines() {
                    let Ok(line) = line else { break };
                    let mut s = sink.lock().unwrap();
                    s.push_str(&line);
                    s.push('\n');
                }
            })
            .unwrap();
        Proc {
            name: name.to_string(),
            child,
            lines,
            stderr,
            last: None,
        }
    }

    /// Reads what arrived; the latest JSON state is kept.
    fn drain(&mut self) {
        while let Ok(line) = self.lines.try_recv() {
            if let Ok(v) = serde_json::from_str::<Value>(&line) {
                self.last = Some(v);
            }
        }
    }

    fn state(&self, key: &str) -> Value {
        self.last
            .as_ref()
            .and_then(|v| v.get(key).cloned())
            .unwrap_or(Value::Null)
    }

    fn stderr(&self) -> String {
        self.stderr.lock().unwrap().clone()
    }

    fn listen(&mut self) -> String {
        wait(&mut [self], "a listening address", |p| {
            p[0].state("listen").is_string()
        });
        self.state("listen")
            .as_str()
            .unwrap()
            .replace("0.0.0.0", "127.0.0.1")
    }

    /// SIGTERM, then the exit status.
    fn terminate(&mut self) -> std::process::ExitStatus {
        let pid = self.child.id().to_string();
        Command::new("kill").args(["-TERM", &pid]).status().unwrap();
        let deadline = app::clock::now().instant + WAIT;
        loop {
            if let Some(status) = self.child.try_wait().unwrap() {
                return status;
            }
            assert!(
                app::clock::now().instant < deadline,
                "{} did not stop",
                self.name
            );
            std::thread::sleep(Duration::from_millis(50));
        }
    }
}

impl Drop for Proc {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// Waits until `done` holds for the processes' latest states.
fn wait(procs: &mut [&mut Proc], what: &str, done: impl Fn(&[&mut Proc]) -> bool) {
    wait_within(procs, what, WAIT, done);
}

/// [`wait`], failing after `limit`.
fn wait_within(
    procs: &mut [&mut Proc],
    what: &str,
    limit: Duration,
    done: impl Fn(&[&mut Proc]) -> bool,
) {
    let started = app::clock::now().instant;
    let deadline = app::clock::now().instant + limit;
    loop {
        for p in procs.iter_mut() {
            p.drain();
        }
        if done(procs) {
            println!("{what}: {:.2} s", started.elapsed().as_secs_f64());
            return;
        }
        if app::clock::now().instant > deadline {
            let states: Vec<String> = procs
                .iter()
                .map(|p| format!("{}: {:?}\n{}", p.name, p.last, p.stderr()))
                .collect();
            panic!("timed out waiting for {what}:\n{}", states.join("\n"));
        }
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// All have `n_ops` ops, one scene hash and `n_peers` peers each.
fn converged(procs: &[&mut Proc], n_ops: u64, n_peers: u64) -> bool {
    let hash = procs[0].state("scene_hash");
    procs.iter().all(|p| {
        p.state("ops").as_u64() == Some(n_ops)
            && p.state("scene_hash") == hash
            && p.state("peers").as_u64() == Some(n_peers)
    })
}

fn peer(name: &str, store: &Path, invite: &str, extra: &[&str]) -> Proc {
    let mut command = sculpt();
    command.args(["peer", "--json", "--no-lan", "--listen", "127.0.0.1:0"]);
    command.args(["--store", store.to_str().unwrap(), "--invite", invite]);
    command.args(extra);
    Proc::spawn(name, command)
}

fn invite() -> String {
    let out = sculpt().arg("invite").output().unwrap();
    assert!(out.status.success(), "{out:?}");
    String::from_utf8(out.stdout).unwrap().trim().to_string()
}

#[test]
fn peers_meet_through_discovery_survive_a_kill_and_sync_offline_edits() {
    let dir = scratch("peers_converge");
    let code = invite();
    let discovery = Proc::spawn("discovery", {
        let mut c = sculpt();
        c.args(["discovery", "--listen", "127.0.0.1:0"]);
        c
    });
    let server = discovery
        .lines
        .recv_timeout(WAIT)
        .unwrap()
        .split_whitespace()
        .find(|w| w.starts_with("127.0.0.1:"))
        .unwrap()
        .trim_end_matches(';')
        .to_string();
    let with_discovery = ["--discovery", server.as_str()];

    // A and C meet through the discovery node; C brings 120 ops.
    let mut a = peer(
        "a",
        &dir.join("a"),
        &code,
        &[
            &with_discovery[..],
            &[
                "--command",
                "new: 1-x^2-y^2-z^2",
                "--command",
                "colour: 1, 0, 0",
            ],
        ]
        .concat(),
    );
    let chats: Vec<String> = (0..120).map(|i| format!("line {i} from c")).collect();
    let mut c_args: Vec<&str> = with_discovery.to_vec();
    for line in &chats {
        c_args.extend(["--command", line.as_str()]);
    }
    let mut c = peer("c", &dir.join("c"), &code, &c_args);
    wait(&mut [&mut a, &mut c], "a and c to converge", |p| {
        converged(p, 122, 1)
    });

    // A second process on A's store is refused, naming the first.
    let second = sculpt()
        .args([
            "peer",
            "--no-lan",
            "--store",
            dir.join("a").to_str().unwrap(),
        ])
        .output()
        .unwrap();
    let said = String::from_utf8_lossy(&second.stderr);
    assert!(!second.status.success(), "{said}");
    assert!(said.contains(&a.child.id().to_string()), "{said}");

    // B joins, is killed mid-catch-up, and restarts from its store.
    let b_store = dir.join("b");
    let mut b = peer(
        "b",
        &b_store,
        &code,
        &[
            &with_discovery[..],
            &[
                "--command",
                "new: (0.5-abs(x)) & (0.5-abs(y)) & (0.5-abs(z))",
                "--command",
                "hello from b",
            ],
        ]
        .concat(),
    );
    wait(&mut [&mut b], "b to start syncing", |p| {
        p[0].state("ops").as_u64().is_some_and(|n| n >= 2)
    });
    b.child.kill().unwrap();
    b.child.wait().unwrap();
    let mut b = peer("b2", &b_store, &code, &with_discovery);
    wait(
        &mut [&mut a, &mut b, &mut c],
        "a, b and c to converge",
        |p| converged(p, 124, 2),
    );

    // D edits offline (no discovery, no dial), stops cleanly, then meets everyone.
    let d_store = dir.join("d");
    let mut d = peer(
        "d",
        &d_store,
        &code,
        &[
            "--command",
            "new: 0.3-sqrt(x^2+y^2+z^2)",
            "--command",
            "offline edit",
        ],
    );
    wait(&mut [&mut d], "d's offline edits", |p| {
        p[0].state("ops").as_u64() == Some(2) && p[0].state("peers").as_u64() == Some(0)
    });
    assert!(d.terminate().success(), "{}", d.stderr());
    let mut d = peer("d2", &d_store, &code, &with_discovery);
    wait(
        &mut [&mut a, &mut b, &mut c, &mut d],
        "all four to converge with d's offline edits",
        |p| converged(p, 126, 3),
    );
    assert_eq!(a.state("objects").as_u64(), Some(3), "{:?}", a.last);

    // A peer with another session's invite is refused, and says why.
    let other = invite();
    let addr = a.listen();
    let mut e = peer("e", &dir.join("e"), &other, &["--dial", addr.as_str()]);
    wait(&mut [&mut e], "e to be refused", |p| {
        p[0].stderr().contains("invites differ")
    });
    e.drain();
    assert_eq!(e.state("peers").as_u64(), Some(0), "{:?}", e.last);
    a.drain();
    assert_eq!(a.state("ops").as_u64(), Some(126));
}
