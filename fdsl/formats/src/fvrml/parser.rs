//! Tokens to a [`Document`]: recursive descent bounded by [`MAX_NESTING_DEPTH`], with skipping
//! of what we do not read done by an iterative brace counter, so no input can overflow the
//! stack. Errors are reported and parsing goes on, so one pass shows every problem.

use std::collections::VecDeque;

use super::document::{Document, Field, KEYWORDS, Node, NodeRef, Pos, Value};
use super::lexer::{Lexer, Tok, Token, clip};
use super::schema::is_known;
use super::{Issues, MAX_FILE_BYTES, MAX_LIST_ITEMS, MAX_NESTING_DEPTH, MAX_NODES};

/// Parses `text` (the file `file`, `None` for the root) into a document, reporting issues.
pub(super) fn parse(text: &str, file: Option<&str>, issues: &mut Issues) -> Document {
    if text.len() > MAX_FILE_BYTES {
        issues.error(
            start_pos(),
            file,
            format!(
                "the text is {} bytes, more than the limit of {MAX_FILE_BYTES}",
                text.len()
            ),
        );
        return Document::default();
    }
    check_header(text, file, issues);
    let mut parser = Parser {
        lexer: Lexer::new(text),
        peeked: VecDeque::new(),
        issues,
        file,
        n_nodes: 0,
        stopped: false,
    };
    let mut nodes = Vec::new();
    while !parser.stopped && parser.peek(0).tok != Tok::Eof {
        if let Some(r) = parser.statement(0) {
            nodes.push(r);
        }
    }
    if let Some(pos) = parser.lexer.typographic_quote {
        parser.warning(
            pos,
            "typographic quotes “...” are read as straight quotes \"...\"".to_string(),
        );
    }
    Document { nodes }
}

fn start_pos() -> Pos {
    Pos {
        line: 1,
        column: 1,
        span: fdsl::syntax::Span::new(0, 0),
    }
}

fn check_header(text: &str, file: Option<&str>, issues: &mut Issues) {
    let first = text.lines().next().unwrap_or("");
    let first = first.trim_start_matches('\u{FEFF}');
    if (first.starts_with("#VRML") || first.starts_with("#X3D"))
        && !first.starts_with("#VRML V2.0 utf8")
    {
        let mut pos = start_pos();
        pos.span = fdsl::syntax::Span::new(0, first.len());
        issues.warning(
            pos,
            file,
            format!(
                "the header `{}` is not `#VRML V2.0 utf8`; read as VRML97",
                clip(first.trim_end())
            ),
        );
    }
}

struct Parser<'a, 'i> {
    lexer: Lexer<'a>,
    peeked: VecDeque<Token<'a>>,
    issues: &'i mut Issues,
    file: Option<&'i str>,
    n_nodes: usize,
    /// Set when a limit stops the parse.
    stopped: bool,
}

/// A description of a token for messages.
fn describe(tok: &Tok<'_>) -> String {
    match tok {
        Tok::Ident(s) => format!("`{}`", clip(s)),
        Tok::Number(v) => format!("the number {v}"),
        Tok::Str(s) => format!("the string \"{}\"", clip(s)),
        Tok::LBrace => "`{`".into(),
        Tok::RBrace => "`}`".into(),
        Tok::LBracket => "`[`".into(),
        Tok::RBracket => "`]`".into(),
        Tok::Colon => "`:`".into(),
        Tok::Dot => "`.`".into(),
        Tok::Error(_) => "an unreadable token".into(),
        Tok::Eof => "the end of the text".into(),
    }
}

impl<'a> Parser<'a, '_> {
    fn error(&mut self, pos: Pos, message: String) {
        self.issues.error(pos, self.file, message);
    }

    fn warning(&mut self, pos: Pos, message: String) {
        self.issues.warning(pos, self.file, message);
    }

    /// The token `n` ahead (`n` <= 1). Unreadable tokens are reported here and passed over.
    fn peek(&mut self, n: usize) -> &Token<'a> {
        while self.peeked.len() <= n {
            let token = self.lexer.next_token();
            if let Tok::Error(message) = token.tok {
                self.error(token.pos, message);
                continue;
            }
            self.peeked.push_back(token);
        }
        &self.peeked[n]
    }

    fn next(&mut self) -> Token<'a> {
        self.peek(0);
        self.peeked.pop_front().unwrap_or(Token {
            tok: Tok::Eof,
            pos: Pos::default(),
        })
    }

    /// A node, `DEF`, `USE` or `NULL`, or a declaration we skip. `None` when nothing was kept.
    fn statement(&mut self, depth: usize) -> Option<NodeRef> {
        let token = self.next();
        let pos = token.pos;
        match token.tok {
            Tok::Ident("DEF") => {
                let name = self.name("DEF")?;
                let (type_name, _) = self.type_name()?;
                self.node(type_name, Some(name), pos, depth)
                    .map(|n| NodeRef::Node(Box::new(n)))
            }
            Tok::Ident("USE") => {
                let name = self.name("USE")?;
                Some(NodeRef::Use { name, pos })
            }
            Tok::Ident("NULL") => Some(NodeRef::Null),
            Tok::Ident("PROTO") => {
                self.skip_proto(pos, false);
                None
            }
            Tok::Ident("EXTERNPROTO") => {
                self.skip_proto(pos, true);
                None
            }
            Tok::Ident("ROUTE") => {
                self.skip_route(pos);
                None
            }
            Tok::Ident(type_name) if self.peek(0).tok == Tok::LBrace => self
                .node(type_name.to_string(), None, pos, depth)
                .map(|n| NodeRef::Node(Box::new(n))),
            Tok::LBrace | Tok::LBracket => {
                self.error(
                    pos,
                    format!("expected a node, found {}", describe(&token.tok)),
                );
                self.skip_balanced(token.tok == Tok::LBrace, pos);
                None
            }
            tok => {
                self.error(pos, format!("expected a node, found {}", describe(&tok)));
                None
            }
        }
    }

    /// The name after `DEF` or `USE`.
    fn name(&mut self, after: &str) -> Option<String> {
        let pos = self.peek(0).pos;
        match self.peek(0).tok {
            Tok::Ident(name) if !KEYWORDS.contains(&name) => {
                let name = name.to_string();
                self.next();
                Some(name)
            }
            ref tok => {
                let found = describe(tok);
                self.error(
                    pos,
                    format!("expected a name after `{after}`, found {found}"),
                );
                None
            }
        }
    }

    /// The node type after `DEF name`.
    fn type_name(&mut self) -> Option<(String, Pos)> {
        let pos = self.peek(0).pos;
        match self.peek(0).tok {
            Tok::Ident(name) if !KEYWORDS.contains(&name) => {
                let name = name.to_string();
                self.next();
                Some((name, pos))
            }
            ref tok => {
                let found = describe(tok);
                self.error(pos, format!("expected a node type, found {found}"));
                None
            }
        }
    }

    /// The body of a node of `type_name` (the next token should be `{`).
    fn node(
        &mut self,
        type_name: String,
        def: Option<String>,
        pos: Pos,
        depth: usize,
    ) -> Option<Node> {
        let open = self.peek(0).pos;
        if self.peek(0).tok != Tok::LBrace {
            let found = describe(&self.peek(0).tok);
            self.error(
                open,
                format!("expected `{{` after `{type_name}`, found {found}"),
            );
            return None;
        }
        if !is_known(&type_name) {
            self.warning(pos, unknown_node_message(&type_name));
            self.skip_balanced(true, open);
            return None;
        }
        if depth >= MAX_NESTING_DEPTH {
            self.error(
                pos,
                format!(
                    "nodes nest deeper than the limit of {MAX_NESTING_DEPTH}; this one is skipped"
                ),
            );
            self.skip_balanced(true, open);
            return None;
        }
        self.n_nodes += 1;
        if self.n_nodes > MAX_NODES {
            self.error(
                pos,
                format!("the text holds more than {MAX_NODES} nodes; reading stops here"),
            );
            self.stopped = true;
            return None;
        }
        self.next();
        let mut node = Node {
            type_name,
            def,
            fields: Vec::new(),
            pos,
        };
        self.body(&mut node, open, depth);
        Some(node)
    }

    /// Fields until the closing `}`.
    fn body(&mut self, node: &mut Node, open: Pos, depth: usize) {
        let mut implicit_children: Option<usize> = None;
        while !self.stopped {
            let pos = self.peek(0).pos;
            let bare_child = match self.peek(0).tok {
                Tok::RBrace => {
                    self.next();
                    return;
                }
                Tok::Eof => {
                    let message = format!(
                        "the `{{` of `{}` at {}:{} is never closed",
                        node.type_name, open.line, open.column
                    );
                    self.error(pos, message);
                    return;
                }
                Tok::Ident("DEF" | "USE" | "NULL" | "PROTO" | "EXTERNPROTO" | "ROUTE") => true,
                Tok::Ident(_) => self.peek(1).tok == Tok::LBrace,
                Tok::LBrace | Tok::LBracket => {
                    let open_brace = self.next().tok == Tok::LBrace;
                    self.error(pos, "expected a field name, found a bracket".into());
                    self.skip_balanced(open_brace, pos);
                    continue;
                }
                _ => {
                    let token = self.next();
                    let found = describe(&token.tok);
                    self.error(pos, format!("expected a field name, found {found}"));
                    continue;
                }
            };
            if bare_child {
                let Some(child) = self.statement(depth + 1) else {
                    continue;
                };
                self.add_child(node, &mut implicit_children, child, pos);
                continue;
            }
            self.field(node, depth);
        }
    }

    fn add_child(
        &mut self,
        node: &mut Node,
        implicit_children: &mut Option<usize>,
        child: NodeRef,
        pos: Pos,
    ) {
        if let Some(idx) = *implicit_children {
            if let Value::NodeList(list) = &mut node.fields[idx].value {
                list.push(child);
            }
            return;
        }
        self.warning(
            pos,
            format!(
                "a node written directly inside `{}` is read as one of its `children`",
                node.type_name
            ),
        );
        *implicit_children = Some(node.fields.len());
        node.fields.push(Field {
            name: "children".into(),
            value: Value::NodeList(vec![child]),
            pos,
            value_pos: pos,
        });
    }

    /// `name [:] value` (the next token is the name).
    fn field(&mut self, node: &mut Node, depth: usize) {
        let token = self.next();
        let Tok::Ident(name) = token.tok else {
            return;
        };
        if KEYWORDS.contains(&name) {
            self.error(token.pos, format!("expected a field name, found `{name}`"));
            return;
        }
        if self.peek(0).tok == Tok::Colon {
            let colon = self.next().pos;
            self.warning(
                colon,
                format!("stray `:` after the field name `{name}` (VRML writes `{name} value`)"),
            );
        }
        let value_pos = self.peek(0).pos;
        if let Some(value) = self.value(name, depth) {
            node.fields.push(Field {
                name: name.to_string(),
                value,
                pos: token.pos,
                value_pos,
            });
        }
    }

    fn value(&mut self, field: &str, depth: usize) -> Option<Value> {
        let pos = self.peek(0).pos;
        let node_follows = self.peek(1).tok == Tok::LBrace;
        match self.peek(0).tok {
            Tok::Ident("TRUE") => {
                self.next();
                Some(Value::Bool(true))
            }
            Tok::Ident("FALSE") => {
                self.next();
                Some(Value::Bool(false))
            }
            Tok::Ident("DEF" | "USE" | "NULL") => self.statement(depth + 1).map(Value::Node),
            Tok::Ident(_) if node_follows => self.statement(depth + 1).map(Value::Node),
            Tok::Number(_) => Some(Value::Numbers(self.numbers())),
            Tok::Str(_) => match self.next().tok {
                Tok::Str(s) => Some(Value::String(s)),
                _ => None,
            },
            Tok::LBracket => self.list(field, depth),
            Tok::RBrace | Tok::Eof | Tok::Ident(_) => {
                let found = describe(&self.peek(0).tok);
                self.error(
                    pos,
                    format!("the field `{field}` has no value (found {found})"),
                );
                None
            }
            _ => {
                let token = self.next();
                let found = describe(&token.tok);
                self.error(
                    pos,
                    format!("the field `{field}` has no value (found {found})"),
                );
                None
            }
        }
    }

    /// A run of numbers.
    fn numbers(&mut self) -> Vec<f64> {
        let mut out = Vec::new();
        while let Tok::Number(v) = self.peek(0).tok {
            let pos = self.next().pos;
            if out.len() == MAX_LIST_ITEMS {
                self.error(
                    pos,
                    format!("more than {MAX_LIST_ITEMS} numbers in a row; the rest are dropped"),
                );
                while let Tok::Number(_) = self.peek(0).tok {
                    self.next();
                }
                break;
            }
            out.push(v);
        }
        out
    }

    /// `[ items ]`, all of one kind.
    fn list(&mut self, field: &str, depth: usize) -> Option<Value> {
        let open = self.next().pos;
        if depth + 1 >= MAX_NESTING_DEPTH {
            self.error(
                open,
                format!("lists nest deeper than the limit of {MAX_NESTING_DEPTH}; skipped"),
            );
            self.skip_rest(1, open);
            return None;
        }
        let mut value = Value::EmptyList;
        let mut n_items = 0usize;
        while !self.stopped {
            let pos = self.peek(0).pos;
            let item = match self.list_item(depth) {
                ListStep::Item(item) => item,
                ListStep::Skipped => continue,
                ListStep::Closed => return Some(value),
                ListStep::End => {
                    let message = format!(
                        "the `[` of `{field}` at {}:{} is never closed",
                        open.line, open.column
                    );
                    self.error(pos, message);
                    return Some(value);
                }
            };
            n_items += 1;
            if n_items > MAX_LIST_ITEMS {
                self.error(
                    pos,
                    format!(
                        "the list holds more than {MAX_LIST_ITEMS} items; the rest are dropped"
                    ),
                );
                self.skip_rest(1, open);
                return Some(value);
            }
            if let Err(message) = push_item(&mut value, item) {
                self.error(pos, message);
            }
        }
        Some(value)
    }

    /// The next item of a list.
    fn list_item(&mut self, depth: usize) -> ListStep {
        let pos = self.peek(0).pos;
        let item = match self.peek(0).tok {
            Tok::RBracket => {
                self.next();
                return ListStep::Closed;
            }
            Tok::Eof => return ListStep::End,
            Tok::Number(v) => Value::Numbers(vec![v]),
            Tok::Ident("TRUE") => Value::Bool(true),
            Tok::Ident("FALSE") => Value::Bool(false),
            Tok::Str(_) => match self.next().tok {
                Tok::Str(s) => return ListStep::Item(Value::String(s)),
                _ => return ListStep::Skipped,
            },
            Tok::Ident(_) => {
                return match self.statement(depth + 1) {
                    Some(r) => ListStep::Item(Value::Node(r)),
                    None => ListStep::Skipped,
                };
            }
            Tok::LBrace | Tok::LBracket => {
                let brace = self.next().tok == Tok::LBrace;
                self.error(pos, "lists cannot hold lists or bare `{ }`".into());
                self.skip_balanced(brace, pos);
                return ListStep::Skipped;
            }
            _ => {
                let token = self.next();
                let found = describe(&token.tok);
                self.error(pos, format!("a list cannot hold {found}"));
                return ListStep::Skipped;
            }
        };
        self.next();
        ListStep::Item(item)
    }

    /// Skips a `{ ... }` or `[ ... ]` whose opening token was just taken or is next.
    fn skip_balanced(&mut self, brace: bool, open: Pos) {
        let opener = if brace { Tok::LBrace } else { Tok::LBracket };
        if self.peek(0).tok == opener && self.peek(0).pos.span == open.span {
            self.next();
        }
        self.skip_rest(1, open);
    }

    /// Skips tokens until `depth` more closers than openers have been seen.
    fn skip_rest(&mut self, mut depth: usize, open: Pos) {
        while depth > 0 {
            match self.next().tok {
                Tok::LBrace | Tok::LBracket => depth += 1,
                Tok::RBrace | Tok::RBracket => depth -= 1,
                Tok::Eof => {
                    self.error(
                        open,
                        "this bracket is never closed (skipping it reached the end)".into(),
                    );
                    return;
                }
                _ => {}
            }
        }
    }

    /// `PROTO name [interface] { body }` or `EXTERNPROTO name [interface] url`.
    fn skip_proto(&mut self, pos: Pos, external: bool) {
        let keyword = if external { "EXTERNPROTO" } else { "PROTO" };
        let name = match self.peek(0).tok {
            Tok::Ident(name) => {
                let name = name.to_string();
                self.next();
                name
            }
            _ => String::new(),
        };
        self.warning(
            pos,
            format!("{keyword} `{name}` is not read (prototypes are not supported); skipped"),
        );
        if self.peek(0).tok == Tok::LBracket {
            let open = self.peek(0).pos;
            self.skip_balanced(false, open);
        }
        match self.peek(0).tok {
            Tok::LBrace if !external => {
                let open = self.peek(0).pos;
                self.skip_balanced(true, open);
            }
            Tok::Str(_) if external => {
                self.next();
            }
            Tok::LBracket if external => {
                let open = self.peek(0).pos;
                self.skip_balanced(false, open);
            }
            _ => {}
        }
    }

    /// `ROUTE a.b TO c.d`.
    fn skip_route(&mut self, pos: Pos) {
        self.warning(
            pos,
            "ROUTE is not read (events are not supported); skipped".into(),
        );
        for _ in 0..7 {
            match self.peek(0).tok {
                Tok::Ident(word) if !matches!(word, "DEF" | "USE" | "PROTO" | "EXTERNPROTO") => {
                    if self.peek(1).tok == Tok::LBrace {
                        return;
                    }
                    self.next();
                }
                Tok::Dot => {
                    self.next();
                }
                _ => return,
            }
        }
    }
}

/// What the next token of a list gave.
enum ListStep {
    /// A value.
    Item(Value),
    /// Something that was reported and passed over.
    Skipped,
    /// The closing `]`.
    Closed,
    /// The end of the text.
    End,
}

/// Adds one item to a list value, keeping the list of one kind.
fn push_item(list: &mut Value, item: Value) -> Result<(), String> {
    match (list, item) {
        (list @ Value::EmptyList, item) => {
            *list = match item {
                Value::Numbers(v) => Value::NumberList(v),
                Value::Bool(b) => Value::Bools(vec![b]),
                Value::String(s) => Value::StringList(vec![s]),
                Value::Node(r) => Value::NodeList(vec![r]),
                other => other,
            };
            Ok(())
        }
        (Value::NumberList(l), Value::Numbers(v)) => {
            l.extend(v);
            Ok(())
        }
        (Value::Bools(l), Value::Bool(b)) => {
            l.push(b);
            Ok(())
        }
        (Value::StringList(l), Value::String(s)) => {
            l.push(s);
            Ok(())
        }
        (Value::NodeList(l), Value::Node(r)) => {
            l.push(r);
            Ok(())
        }
        (list, item) => Err(format!(
            "a list of {} cannot hold {}",
            kind(list),
            kind(&item)
        )),
    }
}

fn kind(value: &Value) -> &'static str {
    match value {
        Value::Bool(_) | Value::Bools(_) => "booleans",
        Value::Numbers(_) | Value::NumberList(_) => "numbers",
        Value::String(_) | Value::StringList(_) => "strings",
        Value::Node(_) | Value::NodeList(_) => "nodes",
        Value::EmptyList => "nothing",
    }
}

fn unknown_node_message(type_name: &str) -> String {
    let why = match type_name {
        "Script" => "scripts are not run",
        "NetConnection" | "BSCollaborate" => "collaboration runs through sculpt's own peers",
        "TextToSpeech" => "speech is not supported",
        "ImageTexture" | "MovieTexture" | "PixelTexture" => "image textures are not supported",
        _ => "FVRML does not read this node type",
    };
    format!("`{type_name}` node skipped ({why})")
}
