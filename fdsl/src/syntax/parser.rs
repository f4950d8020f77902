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

use super::ast::*;
use super::lexer::{Token, TokenKind, tokenize};
use super::{Diagnostic, Span};
use crate::limits::{MAX_DIAGNOSTICS, MAX_NESTING_DEPTH, MAX_SOURCE_BYTES};

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

    fn enter(&mut self, span: Span) -> PResult<()> {
        self.depth += 1;
        if self.depth > MAX_NESTING_DEPTH {
            if !self.too_deep {
                self.too_deep = true;
                self.report(
                    Diagnostic::error(
                        span,
                        format!("the text nests deeper than {MAX_NESTING_DEPTH} levels"),
                    )
                    .with_hint("use intermediate variables to flatten the expression"),
                );
            }
            return Err(Failed);
        }
        Ok(())
    }

    fn leave(&mut self) {
        self.depth -= 1;
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
        self.enter(open.span)?;
        let mut body = Vec::new();
        loop {
            match self.peek().kind {
                TokenKind::RBrace => break,
                TokenKind::Eof => {
                    self.leave();
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
                        self.leave();
                        return Err(Failed);
                    }
                    self.recover_in_block();
                }
            }
        }
        let close = self.bump();
        self.leave();
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
            return Ok(Stmt::If {
                cond,
                then,
                otherwise,
                span: token.span.to(end),
            });
        }
        if self.is_word(token, "while") {
            self.bump();
            self.expect(TokenKind::LParen, "`(` after `while`")?;
            let cond = self.condition()?;
            self.expect(TokenKind::RParen, "`)` to close the condition")?;
            let body = Box::new(self.statement()?);
            let span = token.span.to(body.span());
            return Ok(Stmt::Loop {
                init: None,
                cond: Some(cond),
                step: None,
                body,
                span,
            });
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

    fn expr(&mut self) -> PResult<Expr> {
        self.binary(0)
    }

    fn binary(&mut self, min_level: u8) -> PResult<Expr> {
        let start = self.peek();
        self.enter(start.span)?;
        let result = self.binary_inner(min_level);
        self.leave();
        result
    }

    fn binary_inner(&mut self, min_level: u8) -> PResult<Expr> {
        let mut lhs = self.unary()?;
        while let Some((op, level)) = binary_op(self.peek().kind) {
            if level < min_level {
                break;
            }
            self.bump();
            let rhs = self.binary(level + 1)?;
            let span = lhs.span.to(rhs.span);
            lhs = Expr {
                kind: ExprKind::Binary(op, Box::new(lhs), Box::new(rhs)),
                span,
            };
        }
        Ok(lhs)
    }

    fn unary(&mut self) -> PResult<Expr> {
        let token = self.peek();
        let op = match token.kind {
            TokenKind::Minus => Some(UnaryOp::Neg),
            TokenKind::Bang => Some(UnaryOp::Not),
            TokenKind::Plus => None,
            _ => return self.power(),
        };
        self.bump();
        self.enter(token.span)?;
        let operand = self.unary();
        self.leave();
        let operand = operand?;
        let span = token.span.to(operand.span);
        Ok(match op {
            Some(op) => Expr {
                kind: ExprKind::Unary(op, Box::new(operand)),
                span,
            },
            None => Expr {
                kind: operand.kind,
                span,
            },
        })
    }

    /// `atom ^ unary`, right-associative: `2^3^2` is `2^9` and `x^-2` is allowed.
    fn power(&mut self) -> PResult<Expr> {
        let base = self.atom()?;
        if self.peek().kind != TokenKind::Caret {
            return Ok(base);
        }
        self.bump();
        let exponent = self.unary()?;
        let span = base.span.to(exponent.span);
        Ok(Expr {
            kind: ExprKind::Binary(BinaryOp::Pow, Box::new(base), Box::new(exponent)),
            span,
        })
    }

    fn atom(&mut self) -> PResult<Expr> {
        let token = self.peek();
        match token.kind {
            TokenKind::Number(value) => {
                self.bump();
                if !value.is_finite() {
                    return self.fail(Diagnostic::error(
                        token.span,
                        "this number is too large to represent",
                    ));
                }
                Ok(Expr {
                    kind: ExprKind::Number(value),
                    span: token.span,
                })
            }
            TokenKind::Ident => {
                let name = self.ident("a name")?;
                if self.peek().kind == TokenKind::LParen {
                    return self.call(name);
                }
                Ok(Expr {
                    span: name.span,
                    kind: ExprKind::Var(name.name),
                })
            }
            TokenKind::LParen => {
                self.bump();
                let inner = self.expr()?;
                let close = self.peek();
                if close.kind != TokenKind::RParen {
                    let found = self.describe(close);
                    return self.fail(
                        Diagnostic::error(
                            token.span,
                            format!("this `(` is not closed (found {found})"),
                        )
                        .with_hint("add the missing `)`"),
                    );
                }
                self.bump();
                Ok(Expr {
                    kind: inner.kind,
                    span: token.span.to(close.span),
                })
            }
            TokenKind::Unknown(c) => self.fail(unknown_char(token.span, c)),
            TokenKind::Eof => self.fail(
                Diagnostic::error(token.span, "the text ends where a value was expected")
                    .with_hint("complete the expression"),
            ),
            _ => self.unexpected("a number, a name or `(`"),
        }
    }

    fn call(&mut self, name: Ident) -> PResult<Expr> {
        let open = self.bump();
        let mut args = Vec::new();
        if self.peek().kind != TokenKind::RParen {
            loop {
                args.push(self.expr()?);
                if self.peek().kind == TokenKind::Comma {
                    self.bump();
                } else {
                    break;
                }
            }
        }
        let close = self.peek();
        if close.kind != TokenKind::RParen {
            let found = self.describe(close);
            return self.fail(
                Diagnostic::error(
                    open.span,
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
