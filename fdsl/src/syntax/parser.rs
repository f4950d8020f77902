//! The parser: tokens to [`Program`], with diagnostics instead of failure.
//!
//! Precedence, loosest first: `||`, `&&`, comparisons, `|` (union), `&` and `\`
//! (intersection, difference), `+ -`, `* / %`, prefix `- + !`, then `^` (right-associative,
//! binding tighter than a prefix minus: `-x^2` is `-(x^2)`). Set operators bind looser than
//! arithmetic so that `(2^2-x^2-z^2) & (y+5) & (5-y)` means what its author meant, and
//! tighter than comparisons, so that the thesis's `(r^2-x^2-z^2) & (y+h) & (h-y) >= 0`
//! compares the whole intersection with zero.
//!
//! Dashes printed for a minus sign (the thesis's en dash) read as `-` with a warning.
//!
//! Statements are read by recursive descent, at most [`MAX_STATEMENT_DEPTH`] deep; an
//! expression is read by one loop over an explicit stack, at most [`MAX_NESTING_DEPTH`] deep,
//! so no text can overflow the stack of the thread that parses it.

use super::ast::*;
use super::lexer::{Token, TokenKind, tokenize};
use super::{Diagnostic, Span};
use crate::limits::{MAX_DIAGNOSTICS, MAX_NESTING_DEPTH, MAX_SOURCE_BYTES, MAX_STATEMENT_DEPTH};

/// Parses a whole source text. The program holds whatever could be read; the diagnostics say
/// what could not. A program with no error diagnostic is complete.
pub fn parse(source: &str) -> (Program, Vec<Diagnostic>) {
    if source.len() > MAX_SOURCE_BYTES {
        let d = Diagnostic::error(
            Span::new(MAX_SOURCE_BYTES, source.len()),
            format!(
                "the text is {} bytes long; the limit is {MAX_SOURCE_BYTES}",
                source.len()
            ),
        )
        .with_hint("split the model into several objects or properties");
        return (Program::default(), vec![d]);
    }
    let mut parser = Parser {
        source,
        tokens: tokenize(source),
        pos: 0,
        depth: 0,
        diagnostics: Vec::new(),
        too_deep: false,
    };
    // One warning for the first printed dash read as a minus (a thesis formula has many).
    if let Some(dash) = parser
        .tokens
        .iter()
        .find(|t| t.kind == TokenKind::Minus && t.span.end - t.span.start > 1)
    {
        let d = Diagnostic::warning(
            dash.span,
            format!(
                "read the printed dash `{}` as a minus sign `-`",
                &source[dash.span.start as usize..dash.span.end as usize]
            ),
        )
        .with_hint("type `-` for minus");
        parser.report(d);
    }
    let program = parser.program();
    (program, parser.diagnostics)
}

struct Parser<'a> {
    source: &'a str,
    tokens: Vec<Token>,
    pos: usize,
    /// How many statements enclose the one being read.
    depth: usize,
    diagnostics: Vec<Diagnostic>,
    /// Set once the nesting limit is hit, so that parsing unwinds instead of reporting again.
    too_deep: bool,
}

/// A failed parse of one construct; the diagnostic has already been recorded.
struct Failed;

type PResult<T> = Result<T, Failed>;

const KEYWORDS: [&str; 6] = ["function", "if", "else", "return", "for", "while"];

impl<'a> Parser<'a> {
    fn peek(&self) -> Token {
        self.tokens[self.pos.min(self.tokens.len() - 1)]
    }

    fn peek_at(&self, ahead: usize) -> Token {
        self.tokens[(self.pos + ahead).min(self.tokens.len() - 1)]
    }

    fn bump(&mut self) -> Token {
        let token = self.peek();
        if token.kind != TokenKind::Eof {
            self.pos += 1;
        }
        token
    }

    fn text(&self, span: Span) -> &'a str {
        &self.source[span.range(self.source.len())]
    }

    fn is_word(&self, token: Token, word: &str) -> bool {
        token.kind == TokenKind::Ident && self.text(token.span) == word
    }

    fn report(&mut self, diagnostic: Diagnostic) {
        if self.diagnostics.len() < MAX_DIAGNOSTICS {
            self.diagnostics.push(diagnostic);
        }
    }

    fn fail<T>(&mut self, diagnostic: Diagnostic) -> PResult<T> {
        self.report(diagnostic);
        Err(Failed)
    }

    fn describe(&self, token: Token) -> String {
        match token.kind {
            TokenKind::Eof => "the end of the text".into(),
            TokenKind::Number(_) => format!("the number `{}`", self.text(token.span)),
            TokenKind::Ident => format!("`{}`", self.text(token.span)),
            TokenKind::Unknown(c) => format!("the character `{c}`"),
            _ => format!("`{}`", self.text(token.span)),
        }
    }

    fn unexpected<T>(&mut self, expected: &str) -> PResult<T> {
        let token = self.peek();
        if let TokenKind::Unknown(c) = token.kind {
            return self.fail(unknown_char(token.span, c));
        }
        let found = self.describe(token);
        self.fail(Diagnostic::error(
            token.span,
            format!("expected {expected}, found {found}"),
        ))
    }

    fn expect(&mut self, kind: TokenKind, expected: &str) -> PResult<Token> {
        if self.peek().kind == kind {
            Ok(self.bump())
        } else {
            self.unexpected(expected)
        }
    }

    /// Enters a statement: statements nest by recursion, at most [`MAX_STATEMENT_DEPTH`] deep.
    fn enter(&mut self, span: Span) -> PResult<()> {
        if self.depth >= MAX_STATEMENT_DEPTH {
            return self.nested_too_deeply(
                span,
                format!("statements nest deeper than {MAX_STATEMENT_DEPTH} levels"),
                "each block, `if`, `else` and loop nests one level: flatten them, \
                 or compute parts in variables first",
            );
        }
        self.depth += 1;
        Ok(())
    }

    fn leave(&mut self) {
        self.depth -= 1;
    }

    /// Reports the first nesting past a limit; parsing then unwinds and stops.
    fn nested_too_deeply<T>(&mut self, span: Span, message: String, hint: &str) -> PResult<T> {
        if !self.too_deep {
            self.too_deep = true;
            self.report(Diagnostic::error(span, message).with_hint(hint));
        }
        Err(Failed)
    }

    fn program(&mut self) -> Program {
        self.strip_wrapper();
        let mut program = Program::default();
        while self.peek().kind != TokenKind::Eof && !self.too_deep {
            if self.diagnostics.len() >= MAX_DIAGNOSTICS {
                break;
            }
            let item = if self.is_word(self.peek(), "function") {
                self.function().map(Item::Function)
            } else {
                self.statement().map(Item::Statement)
            };
            match item {
                Ok(item) => program.items.push(item),
                Err(Failed) => self.recover(),
            }
        }
        program
    }

    /// Recognises the `BEGIN ... END` wrapper of the thesis's network messages.
    fn strip_wrapper(&mut self) {
        let n = self.tokens.len();
        let first = self.tokens[0];
        if self.is_word(first, "BEGIN") {
            self.pos = 1;
            self.report(
                Diagnostic::warning(first.span, "ignored the message wrapper `BEGIN`")
                    .with_hint("only the definition between BEGIN and END is needed"),
            );
        }
        if n >= 2 && self.is_word(self.tokens[n - 2], "END") {
            let end = self.tokens[n - 2];
            self.tokens.remove(n - 2);
            self.report(Diagnostic::warning(
                end.span,
                "ignored the message wrapper `END`",
            ));
        }
    }

    /// Skips to just after the next `;` or `}` so that later statements are still checked.
    fn recover(&mut self) {
        if self.too_deep {
            self.pos = self.tokens.len() - 1;
            return;
        }
        let start = self.pos;
        loop {
            match self.peek().kind {
                TokenKind::Eof => break,
                TokenKind::Semi | TokenKind::RBrace => {
                    self.bump();
                    break;
                }
                _ => {
                    self.bump();
                }
            }
        }
        if self.pos == start {
            self.bump();
        }
    }

    fn ident(&mut self, what: &str) -> PResult<Ident> {
        let token = self.peek();
        if token.kind != TokenKind::Ident {
            return self.unexpected(what);
        }
        let name = self.text(token.span);
        if KEYWORDS.contains(&name) {
            return self.fail(Diagnostic::error(
                token.span,
                format!("`{name}` is a keyword, not a name"),
            ));
        }
        self.bump();
        Ok(Ident {
            name: name.to_string(),
            span: token.span,
        })
    }

    fn function(&mut self) -> PResult<FunctionDef> {
        let keyword = self.bump();
        let name = self.ident("a function name after `function`")?;
        self.expect(TokenKind::LParen, "`(` after the function name")?;
        let mut params = Vec::new();
        if self.peek().kind != TokenKind::RParen {
            loop {
                params.push(self.ident("a parameter name")?);
                if self.peek().kind == TokenKind::Comma {
                    self.bump();
                } else {
                    break;
                }
            }
        }
        self.expect(TokenKind::RParen, "`,` or `)` in the parameter list")?;
        let open = self.peek();
        if open.kind != TokenKind::LBrace {
            return self.unexpected("`{` to open the function body");
        }
        let (body, body_span) = self.block()?;
        Ok(FunctionDef {
            name,
            params,
            body,
            span: keyword.span.to(body_span),
        })
    }

    /// `{ statements }`, returning the statements and the span from brace to brace.
    fn block(&mut self) -> PResult<(Vec<Stmt>, Span)> {
        let open = self.bump();
        let mut body = Vec::new();
        loop {
            match self.peek().kind {
                TokenKind::RBrace => break,
                TokenKind::Eof => {
                    let end = self.peek().span;
                    return self.fail(
                        Diagnostic::error(open.span, "this `{` is never closed")
                            .with_hint(format!("add `}}` at the end (byte {})", end.start)),
                    );
                }
                _ => {}
            }
            match self.statement() {
                Ok(s) => body.push(s),
                Err(Failed) => {
                    if self.too_deep {
                        return Err(Failed);
                    }
                    self.recover_in_block();
                }
            }
        }
        let close = self.bump();
        Ok((body, open.span.to(close.span)))
    }

    fn recover_in_block(&mut self) {
        let start = self.pos;
        loop {
            match self.peek().kind {
                TokenKind::Eof | TokenKind::RBrace => break,
                TokenKind::Semi => {
                    self.bump();
                    break;
                }
                _ => {
                    self.bump();
                }
            }
        }
        if self.pos == start && self.peek().kind != TokenKind::RBrace {
            self.bump();
        }
    }

    fn statement(&mut self) -> PResult<Stmt> {
        let token = self.peek();
        self.enter(token.span)?;
        let result = self.statement_inner(token);
        self.leave();
        result
    }

    fn statement_inner(&mut self, token: Token) -> PResult<Stmt> {
        if token.kind == TokenKind::LBrace {
            let (body, span) = self.block()?;
            return Ok(Stmt::Block(body, span));
        }
        if token.kind == TokenKind::Semi {
            self.bump();
            return Ok(Stmt::Block(Vec::new(), token.span));
        }
        if self.is_word(token, "if") {
            return self.if_statement(token);
        }
        if self.is_word(token, "while") {
            return self.while_loop(token);
        }
        if self.is_word(token, "for") {
            return self.for_loop(token);
        }
        if self.is_word(token, "function") {
            return self.fail(
                Diagnostic::error(
                    token.span,
                    "a function can only be defined at the top level",
                )
                .with_hint("close the previous function with `}` first"),
            );
        }
        if self.is_word(token, "else") {
            return self.fail(
                Diagnostic::error(token.span, "`else` without a matching `if`")
                    .with_hint("check the `;` and braces before it"),
            );
        }
        let stmt = if self.is_word(token, "return") {
            self.bump();
            let value = self.expr()?;
            let span = token.span.to(value.span);
            Stmt::Return(value, span)
        } else {
            self.simple_statement()?
        };
        self.end_of_statement()?;
        Ok(stmt)
    }

    /// `if (cond) statement`, with an optional `else statement`; `token` is the `if`.
    fn if_statement(&mut self, token: Token) -> PResult<Stmt> {
        self.bump();
        self.expect(TokenKind::LParen, "`(` after `if`")?;
        let cond = self.condition()?;
        self.expect(TokenKind::RParen, "`)` to close the condition")?;
        let then = Box::new(self.statement()?);
        let mut end = then.span();
        let otherwise = if self.is_word(self.peek(), "else") {
            self.bump();
            let s = self.statement()?;
            end = s.span();
            Some(Box::new(s))
        } else {
            None
        };
        Ok(Stmt::If {
            cond,
            then,
            otherwise,
            span: token.span.to(end),
        })
    }

    /// `while (cond) statement`; `token` is the `while`.
    fn while_loop(&mut self, token: Token) -> PResult<Stmt> {
        self.bump();
        self.expect(TokenKind::LParen, "`(` after `while`")?;
        let cond = self.condition()?;
        self.expect(TokenKind::RParen, "`)` to close the condition")?;
        let body = Box::new(self.statement()?);
        let span = token.span.to(body.span());
        Ok(Stmt::Loop {
            init: None,
            cond: Some(cond),
            step: None,
            body,
            span,
        })
    }

    /// An assignment or a bare expression (no terminator).
    fn simple_statement(&mut self) -> PResult<Stmt> {
        let token = self.peek();
        if token.kind == TokenKind::Ident && self.peek_at(1).kind == TokenKind::Assign {
            let name = self.ident("a variable name")?;
            self.bump();
            let value = self.expr()?;
            return Ok(Stmt::Assign { name, value });
        }
        Ok(Stmt::Expr(self.expr()?))
    }

    fn end_of_statement(&mut self) -> PResult<()> {
        let token = self.peek();
        match token.kind {
            TokenKind::Semi => {
                self.bump();
                Ok(())
            }
            TokenKind::RBrace | TokenKind::Eof => Ok(()),
            _ if self.is_word(token, "else") => Ok(()),
            TokenKind::Assign => self.fail(
                Diagnostic::error(token.span, "only a variable name can stand left of `=`")
                    .with_hint("write `name = expression;`"),
            ),
            TokenKind::RParen => self.fail(
                Diagnostic::error(token.span, "this `)` has no matching `(`")
                    .with_hint("remove it or add `(` before"),
            ),
            _ => {
                let found = self.describe(token);
                if let TokenKind::Unknown(c) = token.kind {
                    return self.fail(unknown_char(token.span, c));
                }
                self.fail(
                    Diagnostic::error(
                        token.span,
                        format!("expected `;` or an operator, found {found}"),
                    )
                    .with_hint("separate statements with `;`"),
                )
            }
        }
    }

    fn for_loop(&mut self, keyword: Token) -> PResult<Stmt> {
        self.bump();
        self.expect(TokenKind::LParen, "`(` after `for`")?;
        let init = if self.peek().kind == TokenKind::Semi {
            None
        } else {
            Some(Box::new(self.simple_statement()?))
        };
        self.expect(TokenKind::Semi, "`;` after the loop's start")?;
        let cond = if self.peek().kind == TokenKind::Semi {
            None
        } else {
            Some(self.condition()?)
        };
        self.expect(TokenKind::Semi, "`;` after the loop's condition")?;
        let step = if self.peek().kind == TokenKind::RParen {
            None
        } else {
            Some(Box::new(self.simple_statement()?))
        };
        self.expect(TokenKind::RParen, "`)` to close the loop header")?;
        let body = Box::new(self.statement()?);
        let span = keyword.span.to(body.span());
        Ok(Stmt::Loop {
            init,
            cond,
            step,
            body,
            span,
        })
    }

    /// A condition; `=` inside one is almost always a mistyped `==`.
    fn condition(&mut self) -> PResult<Expr> {
        let cond = self.expr()?;
        let token = self.peek();
        if token.kind == TokenKind::Assign {
            return self.fail(
                Diagnostic::error(token.span, "`=` assigns; a condition compares")
                    .with_hint("use `==` to test equality"),
            );
        }
        Ok(cond)
    }

    /// An expression, read without recursion: what the text opens (prefixes, `^`, pending
    /// binary operators, parentheses, calls) waits on an explicit stack of [`Open`] frames,
    /// at most [`MAX_NESTING_DEPTH`] of them, so no text can overflow the thread's stack.
    fn expr(&mut self) -> PResult<Expr> {
        let open = &mut Vec::new();
        loop {
            let Some(mut operand) = self.operand(open)? else {
                continue;
            };
            // Close everything the operand completes; come back for the next operand when an
            // operator or a `,` asks for one.
            loop {
                // `atom ^ unary`, right-associative: `2^3^2` is `2^9`, `x^-2` is allowed.
                if self.peek().kind == TokenKind::Caret {
                    let caret = self.bump();
                    self.open(open, Open::Power(operand), caret.span)?;
                    break;
                }
                operand = close_prefixes(open, operand);
                if let Some((op, level)) = binary_op(self.peek().kind) {
                    operand = close_binaries(open, operand, level);
                    let token = self.bump();
                    self.open(open, Open::Binary(operand, op, level), token.span)?;
                    break;
                }
                operand = close_binaries(open, operand, 0);
                match open.pop() {
                    None => return Ok(operand),
                    Some(Open::Paren(paren)) => operand = self.close_paren(paren, operand)?,
                    Some(Open::Call(name, paren, mut args)) => {
                        args.push(operand);
                        if self.peek().kind == TokenKind::Comma {
                            let comma = self.bump();
                            self.open(open, Open::Call(name, paren, args), comma.span)?;
                            break;
                        }
                        operand = self.close_call(name, paren, args)?;
                    }
                    Some(frame @ (Open::Prefix(..) | Open::Power(_) | Open::Binary(..))) => {
                        unreachable!("operators were closed above: {frame:?}")
                    }
                }
            }
        }
    }

    /// Pushes a frame, or reports that the text nests too deeply.
    fn open(&mut self, open: &mut Vec<Open>, frame: Open, span: Span) -> PResult<()> {
        if open.len() >= MAX_NESTING_DEPTH {
            return self.nested_too_deeply(
                span,
                format!("the text nests deeper than {MAX_NESTING_DEPTH} levels"),
                "use intermediate variables to flatten the expression",
            );
        }
        open.push(frame);
        Ok(())
    }

    /// Reads the start of an operand: a prefix, `(` or `name(` opens a frame (`None`); a
    /// number, a name or `name()` is a whole atom.
    fn operand(&mut self, open: &mut Vec<Open>) -> PResult<Option<Expr>> {
        let token = self.peek();
        let prefix = match token.kind {
            TokenKind::Minus => Some(Some(UnaryOp::Neg)),
            TokenKind::Bang => Some(Some(UnaryOp::Not)),
            TokenKind::Plus => Some(None),
            _ => None,
        };
        if let Some(op) = prefix {
            self.bump();
            self.open(open, Open::Prefix(op, token.span), token.span)?;
            return Ok(None);
        }
        match token.kind {
            TokenKind::Number(value) => {
                self.bump();
                if !value.is_finite() {
                    return self.fail(Diagnostic::error(
                        token.span,
                        "this number is too large to represent",
                    ));
                }
                Ok(Some(Expr {
                    kind: ExprKind::Number(value),
                    span: token.span,
                }))
            }
            TokenKind::Ident => {
                let name = self.ident("a name")?;
                if self.peek().kind != TokenKind::LParen {
                    return Ok(Some(Expr {
                        span: name.span,
                        kind: ExprKind::Var(name.name),
                    }));
                }
                let paren = self.bump();
                if self.peek().kind == TokenKind::RParen {
                    return self.close_call(name, paren, Vec::new()).map(Some);
                }
                self.open(open, Open::Call(name, paren, Vec::new()), paren.span)?;
                Ok(None)
            }
            TokenKind::LParen => {
                self.bump();
                self.open(open, Open::Paren(token), token.span)?;
                Ok(None)
            }
            TokenKind::Unknown(c) => self.fail(unknown_char(token.span, c)),
            TokenKind::Eof => self.fail(
                Diagnostic::error(token.span, "the text ends where a value was expected")
                    .with_hint("complete the expression"),
            ),
            _ => self.unexpected("a number, a name or `(`"),
        }
    }

    /// `( inner` followed by the `)` that closes it.
    fn close_paren(&mut self, paren: Token, mut inner: Expr) -> PResult<Expr> {
        let close = self.peek();
        if close.kind != TokenKind::RParen {
            let found = self.describe(close);
            return self.fail(
                Diagnostic::error(
                    paren.span,
                    format!("this `(` is not closed (found {found})"),
                )
                .with_hint("add the missing `)`"),
            );
        }
        self.bump();
        inner.span = paren.span.to(close.span);
        Ok(inner)
    }

    /// `name( args` followed by the `)` that closes them.
    fn close_call(&mut self, name: Ident, paren: Token, args: Vec<Expr>) -> PResult<Expr> {
        let close = self.peek();
        if close.kind != TokenKind::RParen {
            let found = self.describe(close);
            return self.fail(
                Diagnostic::error(
                    paren.span,
                    format!(
                        "the arguments of `{}` are not closed (found {found})",
                        name.name
                    ),
                )
                .with_hint("separate arguments with `,` and close them with `)`"),
            );
        }
        self.bump();
        let span = name.span.to(close.span);
        Ok(Expr {
            kind: ExprKind::Call(name, args),
            span,
        })
    }
}

/// A construct the expression parser has opened and not yet closed.
#[derive(Debug)]
enum Open {
    /// A prefix `-` or `!` (`None`: `+`), applied once its operand is read.
    Prefix(Option<UnaryOp>, Span),
    /// `base ^`, waiting for its exponent.
    Power(Expr),
    /// `lhs op`, waiting for its right operand; the number is the operator's precedence.
    Binary(Expr, BinaryOp, u8),
    /// `(`, waiting for the expression inside.
    Paren(Token),
    /// `name(` and the arguments read so far, waiting for the next one.
    Call(Ident, Token, Vec<Expr>),
}

/// Applies the prefixes and `^`s on top of the stack, innermost first: `-x^2` is `-(x^2)`.
fn close_prefixes(open: &mut Vec<Open>, mut operand: Expr) -> Expr {
    loop {
        operand = match open.pop() {
            Some(Open::Prefix(op, at)) => {
                let span = at.to(operand.span);
                match op {
                    Some(op) => Expr {
                        kind: ExprKind::Unary(op, Box::new(operand)),
                        span,
                    },
                    None => {
                        operand.span = span;
                        operand
                    }
                }
            }
            Some(Open::Power(base)) => {
                let span = base.span.to(operand.span);
                Expr {
                    kind: ExprKind::Binary(BinaryOp::Pow, Box::new(base), Box::new(operand)),
                    span,
                }
            }
            other => {
                open.extend(other);
                return operand;
            }
        };
    }
}

/// Applies the pending binary operators on top of the stack that bind at least as tightly as
/// `level` (all are left-associative).
fn close_binaries(open: &mut Vec<Open>, mut operand: Expr, level: u8) -> Expr {
    while let Some(Open::Binary(_, _, l)) = open.last()
        && *l >= level
    {
        let Some(Open::Binary(lhs, op, _)) = open.pop() else {
            unreachable!("the top frame is a binary operator")
        };
        let span = lhs.span.to(operand.span);
        operand = Expr {
            kind: ExprKind::Binary(op, Box::new(lhs), Box::new(operand)),
            span,
        };
    }
    operand
}

fn binary_op(kind: TokenKind) -> Option<(BinaryOp, u8)> {
    use BinaryOp::*;
    Some(match kind {
        TokenKind::PipePipe => (Or, 1),
        TokenKind::AmpAmp => (And, 2),
        TokenKind::Lt => (Lt, 3),
        TokenKind::Le => (Le, 3),
        TokenKind::Gt => (Gt, 3),
        TokenKind::Ge => (Ge, 3),
        TokenKind::EqEq => (Eq, 3),
        TokenKind::Ne => (Ne, 3),
        TokenKind::Pipe => (Union, 4),
        TokenKind::Amp => (Intersect, 5),
        TokenKind::Backslash => (Subtract, 5),
        TokenKind::Plus => (Add, 6),
        TokenKind::Minus => (Sub, 6),
        TokenKind::Star => (Mul, 7),
        TokenKind::Slash => (Div, 7),
        TokenKind::Percent => (Mod, 7),
        _ => return None,
    })
}

fn unknown_char(span: Span, c: char) -> Diagnostic {
    let d = Diagnostic::error(
        span,
        format!("the character `{c}` is not part of the language"),
    );
    match c {
        '“' | '”' | '"' | '‘' | '’' | '\'' | '«' | '»' => {
            d.with_hint("remove the quotation marks: paste only the definition (the text between BEGIN and END)")
        }
        '×' | '·' | '∙' => d.with_hint("use `*` to multiply"),
        '÷' => d.with_hint("use `/` to divide"),
        'π' => d.with_hint("write `pi`"),
        '²' => d.with_hint("write `^2`"),
        '³' => d.with_hint("write `^3`"),
        '√' => d.with_hint("write `sqrt(...)`"),
        ':' => d.with_hint("remove a label such as `Geometry:`; paste only the definition"),
        _ => d,
    }
}

#[cfg(test)]
mod tests;
