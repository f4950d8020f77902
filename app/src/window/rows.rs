//! The rows the panels list (chat, history, peers, network news), copied from the engine's
//! view when it changes, so that drawing them holds no lock, and the names authors are shown
//! by.

use std::collections::BTreeMap;

use ::app::engine::{ChatRow, Engine, HistoryRow, MAX_NEWS_LINES, PeerRow, lock};

/// What the panels list, as of the view's last generation.
#[derive(Default)]
pub struct Rows {
    /// Chat messages.
    pub chat: Vec<ChatRow>,
    /// Who did what, and whether it counted.
    pub history: Vec<HistoryRow>,
    /// The peers met.
    pub peers: Vec<PeerRow>,
    /// Peers connected now.
    pub n_online: usize,
    /// Display names by short peer id (this peer's and the peers met).
    names: BTreeMap<String, String>,
    /// The latest network news, at most `MAX_NEWS_LINES`.
    pub news: Vec<String>,
    /// Where this window is in the engine's news.
    news_next: u64,
    /// The view generation chat and history were copied at.
    rows_at: Option<u64>,
}

impl Rows {
    /// Copies what changed from `engine`'s view (chat and history only when the view did).
    pub fn refresh(&mut self, engine: &Engine) {
        let view = lock(engine.view());
        if self.rows_at != Some(view.generation()) {
            self.chat = view.chat().to_vec();
            self.history = view.history().to_vec();
            self.rows_at = Some(view.generation());
        }
        self.peers = view.peers().to_vec();
        self.n_online = view.n_online();
        let me = view.peer_id().short();
        drop(view);
        self.names = self
            .peers
            .iter()
            .map(|p| (p.peer.short(), p.name.clone()))
            .chain([(me, engine.presence().name)])
            .collect();
        let (lines, next) = engine.news_since(self.news_next);
        self.news_next = next;
        self.news.extend(lines);
        let excess = self.news.len().saturating_sub(MAX_NEWS_LINES);
        self.news.drain(..excess);
    }

    /// Forgets the session left: its rows are copied again from the next one's view.
    pub fn reset(&mut self) {
        self.rows_at = None;
        self.news.clear();
        self.news_next = 0;
    }

    /// The name a user chose for the author with this short id, with the id: `Bo
    /// (7b3c0dc8)`; just the id when no name is known.
    pub fn display_name(&self, short: &str) -> String {
        match self.names.get(short) {
            Some(name) if name != short => format!("{name} ({short})"),
            _ => short.to_string(),
        }
    }
}
