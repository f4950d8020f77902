//! The abstract syntax tree: programs, statements and expressions, each with its byte span.

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
