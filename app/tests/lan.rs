//! Peers on one LAN find each other with no server and no address given: two `sculpt peer`
//! processes of one session and one of another run inside a private network namespace
//! (`unshare -rn`, loopback only, so nothing leaves the machine); the two of one session
//! announce themselves by DNS-SD, dial each other and converge, each lists the other
//! session, and the third is never connected.
#![allow(
    clippy::unwrap_used,
    reason = "helpers outside #[test] fns unwrap process output"
)]

use std::path::Path;
use std::process::{Command, Stdio};
use std::time::Duration;

use serde_json::Value;

/// Longest wait for convergence.
const WAIT_SECS: u64 = 60;

fn last_state(path: &Path) -> Value {
    let text = std::fs::read_to_string(path).unwrap_or_default();
    text.lines()
        .rev()
        .find_map(|l| serde_json::from_str(l).ok())
        .unwrap_or(Value::Null)
}

#[test]
fn peers_of_one_session_find_each_other_on_the_lan_without_a_server() {
    if Command::new("unshare")
        .args(["-rn", "true"])
        .status()
        .map_or(true, |s| !s.success())
    {
        println!("skipping: cannot make a private network namespace with `unshare -rn`");
        return;
    }
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("lan");
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let bin = env!("CARGO_BIN_EXE_sculpt");
    let invite = |n: &str| {
        let out = Command::new(bin).arg("invite").output().unwrap();
        let code = String::from_utf8(out.stdout).unwrap().trim().to_string();
        std::fs::write(dir.join(n), &code).unwrap();
        code
    };
    let (melon, cube) = (invite("melon.invite"), invite("cube.invite"));
    let peer = |name: &str, code: &str, session: &str, command: &str| {
        let store = dir.join(name);
        let out = dir.join(format!("{name}.json"));
        format!(
            "{bin} peer --store {} --invite {code} --session-name {session} --json \
             --listen 127.0.0.1:0 --command '{command}' > {} 2> {} &",
            store.display(),
            out.display(),
            dir.join(format!("{name}.log")).display()
        )
    };
    // The shell becomes the `sleep` that holds the namespace open, so killing it leaves no
    // process behind but the peers (killed below by their store paths), and none of them holds
    // the test's output: the shell writes to a file.
    let script = format!(
        "ip link set lo up && ip route add 224.0.0.0/4 dev lo || exit 3\n{}\n{}\n{}\n\
         exec sleep {WAIT_SECS}\n",
        peer("a", &melon, "melon", "hello from a"),
        peer("b", &melon, "melon", "hello from b"),
        peer("c", &cube, "cube", "hello from c"),
    );
    let shell_log = dir.join("namespace.log");
    let mut namespace = Command::new("unshare")
        .args(["-rn", "sh", "-c", &script])
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(std::fs::File::create(&shell_log).unwrap())
        .spawn()
        .unwrap();
    let (a, b, c) = (dir.join("a.json"), dir.join("b.json"), dir.join("c.json"));
    let mut converged = false;
    for _ in 0..WAIT_SECS * 10 {
        let (sa, sb) = (last_state(&a), last_state(&b));
        let lists = |s: &Value, name: &str| {
            s["lan"]
                .as_array()
                .is_some_and(|l| l.iter().any(|n| n == name))
        };
        let met = sa["ops"] == 2 && sb["ops"] == 2 && sa["scene_hash"] == sb["scene_hash"];
        if met && lists(&sa, "cube") && lists(&last_state(&c), "melon") {
            converged = true;
            break;
        }
        if let Ok(Some(status)) = namespace.try_wait() {
            let shell = std::fs::read_to_string(&shell_log).unwrap_or_default();
            panic!("the namespace ended early ({status}): {shell}");
        }
        std::thread::sleep(Duration::from_millis(100));
    }
    let logs: Vec<String> = ["a.log", "b.log", "c.log", "namespace.log"]
        .iter()
        .map(|n| std::fs::read_to_string(dir.join(n)).unwrap_or_default())
        .collect();
    let (sa, sc) = (last_state(&a), last_state(&c));
    let _ = namespace.kill();
    let _ = namespace.wait();
    // The peers die with the namespace's shell only when killed themselves.
    let _ = Command::new("pkill")
        .args(["-f", dir.to_str().unwrap()])
        .status();
    assert!(
        converged,
        "a and b never met, or the sessions were not listed: {sa}\n{sc}\n{}",
        logs.join("\n---\n")
    );
    assert_eq!(sa["peers"], 1, "{sa}");
    assert_eq!(
        sc["peers"], 0,
        "the other session's peer is never connected: {sc}"
    );
    assert_eq!(sc["ops"], 1, "{sc}");
    assert!(
        logs[0].contains("(LAN)") || logs[1].contains("(LAN)"),
        "{}",
        logs.join("\n---\n")
    );
}
