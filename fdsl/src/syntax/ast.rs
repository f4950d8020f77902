//! The abstract syntax tree: programs, statements and expressions, each with its byte span.
//!
//! Expressions can be as deep as the text is long (`x+x+...+x` is a left-leaning chain), so
//! nothing walks them by recursion: the parser and the lowering use explicit stacks, and
//! [`Expr`]'s `Drop` takes its subtrees apart iteratively. Statements nest by recursion, at
//! most [`crate::limits::MAX_STATEMENT_DEPTH`] deep from the parser. The derived `Clone`,
//! `PartialEq` and `Debug` do recurse: they are for small trees (tests, messages).

use super::Span;

/// A name and where it was written.
#[derive(Clone, Debug, PartialEq)]
pub struct Ident {
    /// The name as written.
    pub name: String,
    /// Where.
    pub span: Span,
}

/// A whole source text.
#[derive(Clone, Debug, PartialEq, Default)]
pub struct Program {
    /// Top-level items in source order.
    pub items: Vec<Item>,
}

/// A top-level item.
#[derive(Clone, Debug, PartialEq)]
pub enum Item {
    /// `function name(params) { ... }`
    Function(FunctionDef),
    /// A statement outside any function (statement lists such as `x=...; y=...;`).
    Statement(Stmt),
}

/// `function name(a, b, c, t) { body }`
#[derive(Clone, Debug, PartialEq)]
pub struct FunctionDef {
    /// The function's name (`frep`, `parametric_x`, ...).
    pub name: Ident,
    /// Parameter names, bound in order to the coordinate slots.
    pub params: Vec<Ident>,
    /// The statements of the body.
    pub body: Vec<Stmt>,
    /// The whole definition.
    pub span: Span,
}

/// A statement.
#[derive(Clone, Debug, PartialEq)]
pub enum Stmt {
    /// `name = value;`
    Assign {
        /// The variable assigned.
        name: Ident,
        /// The value.
        value: Expr,
    },
    /// `if (cond) then else otherwise`
    If {
        /// The condition.
        cond: Expr,
        /// Taken when the condition is non-zero.
        then: Box<Stmt>,
        /// Taken otherwise.
        otherwise: Option<Box<Stmt>>,
        /// The whole statement.
        span: Span,
    },
    /// `{ ... }`
    Block(Vec<Stmt>, Span),
    /// `return value;`
    Return(Expr, Span),
    /// `for (init; cond; step) body` (each part optional) or `while (cond) body`.
    Loop {
        /// Run once before the loop.
        init: Option<Box<Stmt>>,
        /// Checked before each iteration; absent means always true.
        cond: Option<Expr>,
        /// Run after each iteration.
        step: Option<Box<Stmt>>,
        /// The loop body.
        body: Box<Stmt>,
        /// The whole statement.
        span: Span,
    },
    /// A bare expression: the value of an expression-only program.
    Expr(Expr),
}

impl Stmt {
    /// An empty block, what a statement taken apart is left holding.
    const EMPTY: Stmt = Stmt::Block(Vec::new(), Span { start: 0, end: 0 });

    /// Where the statement stands.
    pub fn span(&self) -> Span {
        match self {
            Stmt::Assign { name, value } => name.span.to(value.span),
            Stmt::If { span, .. }
            | Stmt::Block(_, span)
            | Stmt::Return(_, span)
            | Stmt::Loop { span, .. } => *span,
            Stmt::Expr(e) => e.span,
        }
    }
}

/// Unary operators.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum UnaryOp {
    /// `-a`
    Neg,
    /// `!a`
    Not,
}

/// Binary operators as written.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BinaryOp {
    /// `+`
    Add,
    /// `-`
    Sub,
    /// `*`
    Mul,
    /// `/`
    Div,
    /// `%` (modulo with the sign of the divisor)
    Mod,
    /// `^`
    Pow,
    /// `&`: intersection of solids.
    Intersect,
    /// `|`: union of solids.
    Union,
    /// `\`: difference of solids.
    Subtract,
    /// `<`
    Lt,
    /// `<=`
    Le,
    /// `>`
    Gt,
    /// `>=`
    Ge,
    /// `==`
    Eq,
    /// `!=`
    Ne,
    /// `&&`
    And,
    /// `||`
    Or,
}

/// An expression.
#[derive(Clone, Debug, PartialEq)]
pub struct Expr {
    /// What it is.
    pub kind: ExprKind,
    /// Where.
    pub span: Span,
}

impl Drop for Stmt {
    /// Drops nested statements from a list instead of by recursion: the parser bounds their
    /// depth, but a program built in code may nest deeper.
    fn drop(&mut self) {
        let mut pending: Vec<Stmt> = Vec::new();
        take_statements(self, &mut pending);
        while let Some(mut child) = pending.pop() {
            take_statements(&mut child, &mut pending);
        }
    }
}

/// Moves the statements nested in `s` into `out`, leaving it without any.
fn take_statements(s: &mut Stmt, out: &mut Vec<Stmt>) {
    match s {
        Stmt::Block(body, _) => out.append(body),
        Stmt::If {
            then, otherwise, ..
        } => {
            out.push(std::mem::replace(&mut **then, Stmt::EMPTY));
            out.extend(otherwise.take().map(|o| *o));
        }
        Stmt::Loop {
            init, step, body, ..
        } => {
            out.push(std::mem::replace(&mut **body, Stmt::EMPTY));
            out.extend(init.take().map(|s| *s));
            out.extend(step.take().map(|s| *s));
        }
        Stmt::Assign { .. } | Stmt::Return(..) | Stmt::Expr(_) => {}
    }
}

impl Drop for Expr {
    /// Drops the subtrees from a list instead of by recursion, one level per node, which
    /// would overflow the stack on a long chain.
    fn drop(&mut self) {
        let mut pending: Vec<Expr> = Vec::new();
        take_children(&mut self.kind, &mut pending);
        while let Some(mut child) = pending.pop() {
            take_children(&mut child.kind, &mut pending);
            // `child` now holds no subtree: dropping it does not recurse.
        }
    }
}

/// Moves the subtrees of `kind` into `out`, leaving it a leaf.
fn take_children(kind: &mut ExprKind, out: &mut Vec<Expr>) {
    if matches!(kind, ExprKind::Number(_) | ExprKind::Var(_)) {
        return;
    }
    match std::mem::replace(kind, ExprKind::Number(0.0)) {
        ExprKind::Number(_) | ExprKind::Var(_) => {}
        ExprKind::Unary(_, a) => out.push(*a),
        ExprKind::Binary(_, a, b) => {
            out.push(*a);
            out.push(*b);
        }
        ExprKind::Call(_, args) => out.extend(args),
    }
}

/// The kinds of expression.
#[derive(Clone, Debug, PartialEq)]
pub enum ExprKind {
    /// A number.
    Number(f64),
    /// A variable or named constant.
    Var(String),
    /// A unary operation.
    Unary(UnaryOp, Box<Expr>),
    /// A binary operation.
    Binary(BinaryOp, Box<Expr>, Box<Expr>),
    /// A call `name(args)`.
    Call(Ident, Vec<Expr>),
}
