//! The network flags the window and the headless peer share (`--invite`, `--listen`,
//! `--dial`, `--discovery`, `--no-lan`, `--name`, `--session-name`).

use std::net::SocketAddr;

use app::engine::Network;
use replication::net::invite::Invite;

/// The network flags the window and the headless peer share.
#[derive(clap::Args, Clone, Debug)]
pub struct NetArgs {
    /// Join the session of this invite (from `sculpt invite` or a window's Share).
    #[arg(long, value_name = "CODE", value_parser = parse_invite)]
    pub invite: Option<Invite>,
    /// The UDP address to listen on for peers (port 0 picks a free one).
    #[arg(long, value_name = "ADDR", default_value = "0.0.0.0:0")]
    pub listen: SocketAddr,
    /// Dial this peer, and again whenever not connected (repeatable).
    #[arg(long, value_name = "ADDR")]
    pub dial: Vec<SocketAddr>,
    /// Register with this discovery node to find the session's peers.
    #[arg(long, value_name = "ADDR")]
    pub discovery: Option<SocketAddr>,
    /// Do not announce on or listen to the local network.
    #[arg(long)]
    pub no_lan: bool,
    /// The name other peers see beside your pointer and edits (default: your short id).
    #[arg(long, value_name = "NAME")]
    pub name: Option<String>,
    /// The session's name as the LAN lists it (default: the store directory's name).
    #[arg(long, value_name = "NAME")]
    pub session_name: Option<String>,
}

impl NetArgs {
    /// The engine's network settings.
    pub fn network(&self) -> Network {
        Network {
            listen: self.listen,
            dial: self.dial.clone(),
            discovery: self.discovery,
            lan: !self.no_lan,
        }
    }
}

fn parse_invite(text: &str) -> Result<Invite, String> {
    Invite::parse(text).map_err(|e| e.to_string())
}
