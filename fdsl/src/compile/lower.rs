//! Lowering: the AST of a program to nodes of an expression graph, by symbolic execution.
//!
//! Variables map to graph nodes. `if/else` runs both branches and merges every variable with a
//! `select` on the condition (a choice the interval evaluator can later prune); a condition
//! that folds to a constant runs only its branch. `return` is tracked as a (done, value) pair so
//! that early returns inside branches merge the same way. Loops are unrolled: each trip checks
//! the condition; a loop must finish within [`MAX_LOOP_TRIPS`] trips, and a condition that
//! still depends on the coordinates after [`MAX_SYMBOLIC_TRIPS`] trips is an error.

use std::collections::{BTreeMap, BTreeSet};
use std::sync::Arc;

use super::graph::{Context, GraphFull, Node};
use super::ops::{BinaryOp, TernaryOp, UnaryOp};
use crate::builtins::{FUNCTION_NAMES, arity};
use crate::grid::{Grid, MAX_GRIDS};
use crate::limits::{
    MAX_CALL_ARGS, MAX_LOOP_TRIPS, MAX_OUTPUTS, MAX_STATEMENT_DEPTH, MAX_STATEMENT_FUEL,
    MAX_VARIABLES,
};
use crate::syntax::ast::{self, Expr, ExprKind, FunctionDef, Item, Program, Stmt};
use crate::syntax::{Diagnostic, Span};

/// The most trips a loop whose condition depends on the coordinates is unrolled for.
pub const MAX_SYMBOLIC_TRIPS: usize = 32;

/// How the set operators `&`, `|` and `\` are computed (thesis section 7.1).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum SetOps {
    /// `min`/`max`: exact distances are kept where one operand dominates, with creases.
    #[default]
    MinMax,
    /// R-functions of the R0 system: smooth everywhere but on the seam, `C^1` values.
    RFunction,
}

/// The grids a formula may call, by name (see [`crate::grid`]).
pub type Grids = Arc<[Arc<Grid>]>;

/// Options of the compiler.
#[derive(Clone, Debug, Default, PartialEq, Eq, Hash)]
pub struct Options {
    /// What `& | \` mean.
    pub set_ops: SetOps,
    /// The most graph nodes the program may unroll to, below
    /// [`crate::limits::MAX_GRAPH_NODES`] (`None`: that limit); objects' formulas use
    /// [`crate::limits::formula_node_budget`].
    pub max_graph_nodes: Option<usize>,
    /// Sampled grids the program may call by name, `name(x, y, z)`: at most
    /// [`MAX_GRIDS`], with distinct names.
    pub grids: Grids,
}

/// A lowered program: the graph and its named outputs.
#[derive(Clone, Debug)]
pub struct Lowered {
    /// The graph.
    pub context: Context,
    /// Named outputs in definition order.
    pub outputs: Vec<(String, Node)>,
    /// Which coordinate slots the program reads.
    pub inputs_used: [bool; 4],
}

/// The built-in names of the coordinate slots outside functions.
const INPUT_NAMES: [(&str, u8); 7] = [
    ("x", 0),
    ("y", 1),
    ("z", 2),
    ("t", 3),
    ("u", 0),
    ("v", 1),
    ("w", 2),
];

/// Lowers a parsed program. Returns `None` when any error was reported.
pub fn lower(program: &Program, options: Options) -> (Option<Lowered>, Vec<Diagnostic>) {
    let mut lowerer = Lowerer {
        ctx: Context::with_limit(
            options
                .max_graph_nodes
                .unwrap_or(crate::limits::MAX_GRAPH_NODES),
        ),
        options,
        diagnostics: Vec::new(),
        fuel: 0,
        depth: 0,
        inputs_used: [false; 4],
    };
    let outputs = match check_grids(&lowerer.options.grids) {
        Ok(()) => lowerer.program(program),
        Err(d) => {
            lowerer.report(d);
            None
        }
    };
    let failed = lowerer.diagnostics.iter().any(Diagnostic::is_error);
    let lowered = match outputs {
        Some(outputs) if !failed => Some(Lowered {
            context: lowerer.ctx,
            outputs,
            inputs_used: lowerer.inputs_used,
        }),
        _ => None,
    };
    (lowered, lowerer.diagnostics)
}

/// The options' grids are few enough and distinctly named.
fn check_grids(grids: &[Arc<Grid>]) -> Result<(), Diagnostic> {
    let whole = Span::new(0, 0);
    if grids.len() > MAX_GRIDS {
        return Err(Diagnostic::error(
            whole,
            format!(
                "{} grids were given; a formula may call at most {MAX_GRIDS}",
                grids.len()
            ),
        ));
    }
    for (i, g) in grids.iter().enumerate() {
        if grids[..i].iter().any(|h| h.name() == g.name()) {
            return Err(Diagnostic::error(
                whole,
                format!("two grids are named `{}`", g.name()),
            ));
        }
    }
    Ok(())
}

/// A lowering step failed; its diagnostic is recorded (or it follows one already recorded).
#[derive(Debug)]
struct Failed;

type LResult<T> = Result<T, Failed>;

#[derive(Clone, Debug, PartialEq)]
enum Value {
    Defined(Node),
    /// Assigned on some paths only.
    Partial,
    /// Its definition failed; uses report nothing more.
    Poisoned,
}

#[derive(Clone, Debug)]
struct Env {
    vars: BTreeMap<String, Value>,
    /// Non-zero where a `return` has run.
    done: Node,
    /// The returned value where `done` is non-zero.
    ret: Option<Node>,
    /// The names bound to coordinates in this scope.
    inputs: BTreeMap<String, u8>,
}

struct Lowerer {
    ctx: Context,
    options: Options,
    diagnostics: Vec<Diagnostic>,
    fuel: usize,
    /// How many statements enclose the one being run.
    depth: usize,
    inputs_used: [bool; 4],
}

impl Lowerer {
    fn report(&mut self, d: Diagnostic) {
        if self.diagnostics.len() < crate::limits::MAX_DIAGNOSTICS {
            self.diagnostics.push(d);
        }
    }

    fn fail<T>(&mut self, d: Diagnostic) -> LResult<T> {
        self.report(d);
        Err(Failed)
    }

    fn full<T>(&mut self, span: Span, r: Result<T, GraphFull>) -> LResult<T> {
        match r {
            Ok(v) => Ok(v),
            Err(e) if e.limit < crate::limits::MAX_GRAPH_NODES => {
                self.fail(Diagnostic::error(span, e.to_string()).with_hint(format!(
                    "an object's formula may unroll to {} operations plus {} per character \
                     of its text: run loops fewer times",
                    crate::limits::MAX_FORMULA_NODES_BASE,
                    crate::limits::MAX_FORMULA_NODES_PER_BYTE
                )))
            }
            Err(e) => self
                .fail(Diagnostic::error(span, e.to_string()).with_hint("simplify the definition")),
        }
    }

    fn constant(&mut self, span: Span, v: f64) -> LResult<Node> {
        let r = self.ctx.constant(v);
        self.full(span, r)
    }

    fn unary(&mut self, span: Span, op: UnaryOp, a: Node) -> LResult<Node> {
        let r = self.ctx.unary(op, a);
        self.full(span, r)
    }

    fn binary(&mut self, span: Span, op: BinaryOp, a: Node, b: Node) -> LResult<Node> {
        let r = self.ctx.binary(op, a, b);
        self.full(span, r)
    }

    fn ternary(&mut self, span: Span, op: TernaryOp, a: Node, b: Node, c: Node) -> LResult<Node> {
        let r = self.ctx.ternary(op, a, b, c);
        self.full(span, r)
    }

    fn program(&mut self, program: &Program) -> Option<Vec<(String, Node)>> {
        let functions: Vec<&FunctionDef> = program
            .items
            .iter()
            .filter_map(|i| {
                if let Item::Function(f) = i {
                    Some(f)
                } else {
                    None
                }
            })
            .collect();
        let statements: Vec<&Stmt> = program
            .items
            .iter()
            .filter_map(|i| {
                if let Item::Statement(s) = i {
                    Some(s)
                } else {
                    None
                }
            })
            .collect();
        if functions.is_empty() && statements.is_empty() {
            if self.diagnostics.iter().any(Diagnostic::is_error) {
                return None;
            }
            self.report(
                Diagnostic::error(Span::default(), "the definition is empty").with_hint(
                    "write an expression such as `1-x^2-y^2-z^2`, or a constant such as `0.8`",
                ),
            );
            return None;
        }
        if !functions.is_empty() {
            if let Some(s) = statements.first() {
                self.report(
                    Diagnostic::error(s.span(), "statements outside a function")
                        .with_hint("move them into the function body, or remove the function"),
                );
                return None;
            }
            return self.functions(&functions);
        }
        self.statement_list(&statements)
    }

    fn functions(&mut self, functions: &[&FunctionDef]) -> Option<Vec<(String, Node)>> {
        let mut outputs: Vec<(String, Node)> = Vec::new();
        let mut seen: BTreeMap<String, Span> = BTreeMap::new();
        for f in functions {
            let name = output_name(&f.name.name);
            if let Some(first) = seen.get(&name) {
                self.report(
                    Diagnostic::error(f.name.span, format!("`{}` is defined twice", f.name.name))
                        .with_hint(format!(
                            "the first definition starts at byte {}",
                            first.start
                        )),
                );
                continue;
            }
            seen.insert(name.clone(), f.name.span);
            if let Ok(node) = self.function(f) {
                outputs.push((name, node));
            }
        }
        Some(outputs)
    }

    fn function(&mut self, f: &FunctionDef) -> LResult<Node> {
        if f.params.len() > 4 {
            return self.fail(
                Diagnostic::error(f.params[4].span, "a function takes at most four parameters")
                    .with_hint("the parameters stand for x, y, z, t (or u, v, w, t)"),
            );
        }
        let mut inputs = BTreeMap::new();
        for (slot, p) in f.params.iter().enumerate() {
            if inputs.insert(p.name.clone(), slot as u8).is_some() {
                return self.fail(Diagnostic::error(
                    p.span,
                    format!("the parameter `{}` is named twice", p.name),
                ));
            }
        }
        let zero = self.constant(f.span, 0.0)?;
        let mut env = Env {
            vars: BTreeMap::new(),
            done: zero,
            ret: None,
            inputs,
        };
        self.block(&f.body, &mut env);
        if self.diagnostics.iter().any(Diagnostic::is_error) {
            return Err(Failed);
        }
        let end = Span::new(f.span.end.saturating_sub(1) as usize, f.span.end as usize);
        match (self.ctx.const_value(env.done), env.ret) {
            (Some(d), Some(ret)) if d != 0.0 => Ok(ret),
            (_, None) => self.fail(
                Diagnostic::error(end, format!("`{}` never returns a value", f.name.name))
                    .with_hint("end the function with `return <value>;`"),
            ),
            _ => self.fail(
                Diagnostic::error(
                    end,
                    format!("`{}` can reach its end without returning", f.name.name),
                )
                .with_hint("add a `return` after the `if`, or in every branch"),
            ),
        }
    }

    fn statement_list(&mut self, statements: &[&Stmt]) -> Option<Vec<(String, Node)>> {
        let zero = self.constant(Span::default(), 0.0).ok()?;
        let inputs = INPUT_NAMES
            .iter()
            .map(|(n, s)| (n.to_string(), *s))
            .collect();
        let mut env = Env {
            vars: BTreeMap::new(),
            done: zero,
            ret: None,
            inputs,
        };
        let mut order: Vec<String> = Vec::new();
        let mut value: Option<Node> = None;
        for (idx, s) in statements.iter().enumerate() {
            if let Stmt::Assign { name, .. } = s
                && !order.contains(&name.name)
            {
                order.push(name.name.clone());
            }
            if let Stmt::Expr(e) = s {
                if idx + 1 != statements.len() {
                    self.report(
                        Diagnostic::error(e.span, "a value on its own must be the last statement")
                            .with_hint("assign it to a variable: `name = ...;`"),
                    );
                    continue;
                }
                if let Ok(node) = self.expr(e, &env) {
                    value = Some(node);
                }
                continue;
            }
            self.statement(s, &mut env);
        }
        if self.diagnostics.iter().any(Diagnostic::is_error) {
            return None;
        }
        self.list_outputs(statements, &env, order, value)
    }

    /// The outputs of `statements`, which ran in `env` without error: the assigned names in
    /// `order`, after the value (`value`, or what every branch returns).
    fn list_outputs(
        &mut self,
        statements: &[&Stmt],
        env: &Env,
        order: Vec<String>,
        mut value: Option<Node>,
    ) -> Option<Vec<(String, Node)>> {
        let mut outputs = Vec::new();
        for name in order {
            if let Some(Value::Defined(node)) = env.vars.get(&name) {
                outputs.push((name, *node));
            }
        }
        if let Some(ret) = env.ret {
            let done_const = self.ctx.const_value(env.done);
            if done_const != Some(1.0) {
                self.report(
                    Diagnostic::error(
                        statements[statements.len() - 1].span(),
                        "the text can end without returning",
                    )
                    .with_hint("add a `return` in every branch"),
                );
                return None;
            }
            value = Some(ret);
        }
        if let Some(v) = value {
            outputs.insert(0, ("value".to_string(), v));
        }
        if outputs.len() > MAX_OUTPUTS {
            self.report(Diagnostic::error(
                Span::default(),
                format!("the text defines more than {MAX_OUTPUTS} outputs"),
            ));
            return None;
        }
        if outputs.is_empty() {
            self.report(
                Diagnostic::error(statements[0].span(), "the text defines no value")
                    .with_hint("end with an expression, a `return`, or assignments such as `x=...; y=...; z=...;`"),
            );
            return None;
        }
        Some(outputs)
    }

    fn block(&mut self, body: &[Stmt], env: &mut Env) {
        for s in body {
            if self.ctx.const_value(env.done).is_some_and(|d| d != 0.0) {
                break;
            }
            self.statement(s, env);
            if self.diagnostics.len() >= crate::limits::MAX_DIAGNOSTICS {
                break;
            }
        }
    }

    /// Runs one statement. Errors are recorded; the statement's variables are poisoned so that
    /// later statements are still checked without cascading reports. Statements nest by
    /// recursion, so their depth is checked here too (the parser's limit, for programs
    /// built in code).
    fn statement(&mut self, s: &Stmt, env: &mut Env) {
        if self.depth >= MAX_STATEMENT_DEPTH {
            self.report(
                Diagnostic::error(
                    s.span(),
                    format!("statements nest deeper than {MAX_STATEMENT_DEPTH} levels"),
                )
                .with_hint("flatten the blocks, `if`s and loops"),
            );
            return;
        }
        self.depth += 1;
        self.run_statement(s, env);
        self.depth -= 1;
    }

    fn run_statement(&mut self, s: &Stmt, env: &mut Env) {
        self.fuel += 1;
        if self.fuel > MAX_STATEMENT_FUEL {
            if self.fuel == MAX_STATEMENT_FUEL + 1 {
                self.report(
                    Diagnostic::error(
                        s.span(),
                        format!("the program runs more than {MAX_STATEMENT_FUEL} statements"),
                    )
                    .with_hint("reduce the loop counts"),
                );
            }
            return;
        }
        match s {
            Stmt::Assign { name, value } => self.assign(name, value, env),
            Stmt::Block(body, _) => self.block(body, env),
            Stmt::Return(e, _) => self.return_statement(e, env),
            Stmt::If {
                cond,
                then,
                otherwise,
                ..
            } => self.if_statement(cond, then, otherwise.as_deref(), env),
            Stmt::Loop {
                init,
                cond,
                step,
                body,
                span,
            } => self.loop_statement(
                init.as_deref(),
                cond.as_ref(),
                step.as_deref(),
                body,
                *span,
                env,
            ),
            Stmt::Expr(e) => {
                self.report(
                    Diagnostic::error(e.span, "a value on its own does nothing here")
                        .with_hint("assign it (`g = ...;`) or return it (`return ...;`)"),
                );
            }
        }
    }

    /// `name = value;`
    fn assign(&mut self, name: &ast::Ident, value: &Expr, env: &mut Env) {
        let v = match self.expr(value, env) {
            Ok(node) => Value::Defined(node),
            Err(Failed) => Value::Poisoned,
        };
        if !env.vars.contains_key(&name.name) && env.vars.len() >= MAX_VARIABLES {
            self.report(Diagnostic::error(
                name.span,
                format!("more than {MAX_VARIABLES} variables"),
            ));
            return;
        }
        env.vars.insert(name.name.clone(), v);
    }

    /// `return e;`: the value where nothing returned before, and done from here on.
    fn return_statement(&mut self, e: &Expr, env: &mut Env) {
        let Ok(value) = self.expr(e, env) else {
            let one = self.constant(e.span, 1.0);
            if let Ok(one) = one {
                env.done = one;
            }
            return;
        };
        let ret = match env.ret {
            Some(prev) => self.ternary(e.span, TernaryOp::Select, env.done, prev, value),
            None => Ok(value),
        };
        let one = self.constant(e.span, 1.0);
        if let (Ok(ret), Ok(one)) = (ret, one) {
            env.ret = Some(ret);
            env.done = one;
        }
    }

    fn if_statement(&mut self, cond: &Expr, then: &Stmt, otherwise: Option<&Stmt>, env: &mut Env) {
        let Ok(c) = self.expr(cond, env) else {
            // Check the branches anyway, for more diagnostics.
            let mut scratch = env.clone();
            self.statement(then, &mut scratch);
            if let Some(o) = otherwise {
                self.statement(o, env);
            }
            return;
        };
        if let Some(value) = self.ctx.const_value(c) {
            if value != 0.0 {
                self.statement(then, env);
            } else if let Some(o) = otherwise {
                self.statement(o, env);
            }
            return;
        }
        let mut then_env = env.clone();
        self.statement(then, &mut then_env);
        let mut else_env = env.clone();
        if let Some(o) = otherwise {
            self.statement(o, &mut else_env);
        }
        if let Ok(merged) = self.merge(cond.span, c, then_env, else_env) {
            *env = merged;
        }
    }

    fn merge(&mut self, span: Span, c: Node, a: Env, b: Env) -> LResult<Env> {
        let names: BTreeSet<&String> = a.vars.keys().chain(b.vars.keys()).collect();
        let mut vars = BTreeMap::new();
        for name in names {
            let v = match (a.vars.get(name), b.vars.get(name)) {
                (Some(Value::Defined(x)), Some(Value::Defined(y))) => {
                    Value::Defined(self.ternary(span, TernaryOp::Select, c, *x, *y)?)
                }
                (Some(Value::Poisoned), _) | (_, Some(Value::Poisoned)) => Value::Poisoned,
                _ => Value::Partial,
            };
            vars.insert(name.clone(), v);
        }
        let done = self.ternary(span, TernaryOp::Select, c, a.done, b.done)?;
        let ret = match (a.ret, b.ret) {
            (Some(x), Some(y)) => Some(self.ternary(span, TernaryOp::Select, c, x, y)?),
            (Some(x), None) | (None, Some(x)) => Some(x),
            (None, None) => None,
        };
        Ok(Env {
            vars,
            done,
            ret,
            inputs: a.inputs,
        })
    }

    fn loop_statement(
        &mut self,
        init: Option<&Stmt>,
        cond: Option<&Expr>,
        step: Option<&Stmt>,
        body: &Stmt,
        span: Span,
        env: &mut Env,
    ) {
        if let Some(init) = init {
            self.statement(init, env);
        }
        let errors_before = self.error_count();
        let mut symbolic_trips = 0;
        for trip in 0.. {
            if self.ctx.const_value(env.done).is_some_and(|d| d != 0.0)
                || self.error_count() > errors_before
            {
                return;
            }
            let c = match cond {
                Some(cond) => match self.expr(cond, env) {
                    Ok(c) => c,
                    Err(Failed) => return,
                },
                None => match self.constant(span, 1.0) {
                    Ok(c) => c,
                    Err(Failed) => return,
                },
            };
            let constant = self.ctx.const_value(c);
            if constant == Some(0.0) {
                return;
            }
            if trip >= MAX_LOOP_TRIPS {
                self.report(
                    Diagnostic::error(
                        span,
                        format!("this loop runs more than {MAX_LOOP_TRIPS} times"),
                    )
                    .with_hint("loops must end after a bounded number of trips"),
                );
                return;
            }
            let mut body_env = env.clone();
            self.statement(body, &mut body_env);
            if let Some(step) = step {
                self.statement(step, &mut body_env);
            }
            if constant.is_some() {
                *env = body_env;
                continue;
            }
            symbolic_trips += 1;
            if symbolic_trips > MAX_SYMBOLIC_TRIPS {
                self.report(
                    Diagnostic::error(span, format!(
                        "this loop's condition still depends on the coordinates after {MAX_SYMBOLIC_TRIPS} trips"
                    ))
                    .with_hint("count the trips with a constant bound, e.g. `for (i=0; i<10; i=i+1)`"),
                );
                return;
            }
            let skip_env = env.clone();
            match self.merge(span, c, body_env, skip_env) {
                Ok(merged) => *env = merged,
                Err(Failed) => return,
            }
        }
    }

    fn error_count(&self) -> usize {
        self.diagnostics.iter().filter(|d| d.is_error()).count()
    }

    /// Lowers an expression without recursion (a chain such as `x+x+...+x` is as deep as the
    /// text is long): a post-order walk over an explicit stack, in the order a recursive walk
    /// would take, so nodes and diagnostics come in source order.
    fn expr(&mut self, root: &Expr, env: &Env) -> LResult<Node> {
        enum Step<'e> {
            /// Lower this subtree.
            Enter(&'e Expr),
            /// Its operands are lowered (on top of `values`): apply its operation.
            Exit(&'e Expr, Option<Arc<Grid>>),
        }
        let mut steps = vec![Step::Enter(root)];
        let mut values: Vec<LResult<Node>> = Vec::new();
        let mut operands: Vec<Node> = Vec::new();
        while let Some(step) = steps.pop() {
            match step {
                Step::Enter(e) => match &e.kind {
                    ExprKind::Number(v) => values.push(self.constant(e.span, *v)),
                    ExprKind::Var(name) => values.push(self.variable(name, e.span, env)),
                    ExprKind::Unary(_, a) => {
                        steps.push(Step::Exit(e, None));
                        steps.push(Step::Enter(a));
                    }
                    ExprKind::Binary(_, a, b) => {
                        steps.push(Step::Exit(e, None));
                        steps.push(Step::Enter(b));
                        steps.push(Step::Enter(a));
                    }
                    ExprKind::Call(name, args) => match self.callee(name, args, e.span) {
                        Ok(grid) => {
                            steps.push(Step::Exit(e, grid));
                            steps.extend(args.iter().rev().map(Step::Enter));
                        }
                        Err(Failed) => values.push(Err(Failed)),
                    },
                },
                Step::Exit(e, grid) => {
                    let n_args = match &e.kind {
                        ExprKind::Unary(..) => 1,
                        ExprKind::Binary(..) => 2,
                        ExprKind::Call(_, args) => args.len(),
                        ExprKind::Number(_) | ExprKind::Var(_) => 0,
                    };
                    operands.clear();
                    let mut failed = false;
                    for v in values.drain(values.len() - n_args..) {
                        match v {
                            Ok(node) => operands.push(node),
                            Err(Failed) => failed = true,
                        }
                    }
                    let value = if failed {
                        Err(Failed)
                    } else {
                        self.apply(e, grid, &operands)
                    };
                    values.push(value);
                }
            }
        }
        assert_eq!(values.len(), 1, "an expression lowers to one value");
        values.pop().unwrap_or(Err(Failed))
    }

    /// The operation of `e` on its lowered operands.
    fn apply(&mut self, e: &Expr, grid: Option<Arc<Grid>>, n: &[Node]) -> LResult<Node> {
        let span = e.span;
        match &e.kind {
            ExprKind::Unary(op, _) => {
                let op = match op {
                    ast::UnaryOp::Neg => UnaryOp::Neg,
                    ast::UnaryOp::Not => UnaryOp::Not,
                };
                self.unary(span, op, n[0])
            }
            ExprKind::Binary(op, _, _) => self.binary_expr(span, *op, n[0], n[1]),
            ExprKind::Call(name, _) => match grid {
                Some(grid) => {
                    let sampled = self.ctx.sample(&grid, n[0], n[1], n[2]);
                    self.full(span, sampled)
                }
                None => self.builtin(&name.name, n, span),
            },
            ExprKind::Number(_) | ExprKind::Var(_) => {
                unreachable!("leaves are lowered when entered")
            }
        }
    }

    fn binary_expr(&mut self, span: Span, op: ast::BinaryOp, a: Node, b: Node) -> LResult<Node> {
        use ast::BinaryOp as A;
        let r_functions = self.options.set_ops == SetOps::RFunction;
        match op {
            A::Add => self.binary(span, BinaryOp::Add, a, b),
            A::Sub => self.binary(span, BinaryOp::Sub, a, b),
            A::Mul => self.binary(span, BinaryOp::Mul, a, b),
            A::Div => self.binary(span, BinaryOp::Div, a, b),
            A::Mod => self.binary(span, BinaryOp::Mod, a, b),
            A::Pow => self.binary(span, BinaryOp::Pow, a, b),
            A::Intersect => self.binary(
                span,
                if r_functions {
                    BinaryOp::RAnd
                } else {
                    BinaryOp::Min
                },
                a,
                b,
            ),
            A::Union => self.binary(
                span,
                if r_functions {
                    BinaryOp::ROr
                } else {
                    BinaryOp::Max
                },
                a,
                b,
            ),
            A::Subtract => {
                let nb = self.unary(span, UnaryOp::Neg, b)?;
                self.binary(
                    span,
                    if r_functions {
                        BinaryOp::RAnd
                    } else {
                        BinaryOp::Min
                    },
                    a,
                    nb,
                )
            }
            A::Lt => self.binary(span, BinaryOp::Lt, a, b),
            A::Le => self.binary(span, BinaryOp::Le, a, b),
            A::Gt => self.binary(span, BinaryOp::Lt, b, a),
            A::Ge => self.binary(span, BinaryOp::Le, b, a),
            A::Eq => self.binary(span, BinaryOp::Eq, a, b),
            A::Ne => {
                let eq = self.binary(span, BinaryOp::Eq, a, b)?;
                self.unary(span, UnaryOp::Not, eq)
            }
            A::And => self.binary(span, BinaryOp::And, a, b),
            A::Or => self.binary(span, BinaryOp::Or, a, b),
        }
    }

    fn variable(&mut self, name: &str, span: Span, env: &Env) -> LResult<Node> {
        match env.vars.get(name) {
            Some(Value::Defined(node)) => return Ok(*node),
            Some(Value::Poisoned) => return Err(Failed),
            Some(Value::Partial) => {
                return self.fail(
                    Diagnostic::error(
                        span,
                        format!("`{name}` is not assigned on every path before this use"),
                    )
                    .with_hint(format!(
                        "assign `{name}` before the `if`, or in every branch"
                    )),
                );
            }
            None => {}
        }
        if let Some(&slot) = env.inputs.get(name) {
            self.inputs_used[slot as usize] = true;
            let r = self.ctx.input(slot);
            return self.full(span, r);
        }
        if name == "pi" || name == "PI" {
            return self.constant(span, std::f64::consts::PI);
        }
        let mut candidates: Vec<&str> = env.vars.keys().map(String::as_str).collect();
        candidates.extend(env.inputs.keys().map(String::as_str));
        candidates.push("pi");
        let mut d = Diagnostic::error(span, format!("unknown name `{name}`"));
        if FUNCTION_NAMES.contains(&name) {
            d = d.with_hint(format!("`{name}` is a function: write `{name}(...)`"));
        } else if env.inputs.len() < INPUT_NAMES.len()
            && ["x", "y", "z", "t", "u", "v", "w"].contains(&name)
        {
            d = d.with_hint(format!("add `{name}` to the function's parameters"));
        } else if let Some(best) = suggest(name, &candidates) {
            d = d.with_hint(format!("did you mean `{best}`?"));
        } else {
            d = d.with_hint("assign it before use, e.g. `a = 1;`");
        }
        self.fail(d)
    }

    /// Checks a call's function and argument count before its arguments are lowered; the
    /// grid it samples, if it names one.
    fn callee(
        &mut self,
        name: &ast::Ident,
        args: &[Expr],
        span: Span,
    ) -> LResult<Option<Arc<Grid>>> {
        let f = name.name.as_str();
        let grid = self.options.grids.iter().find(|g| g.name() == f).cloned();
        let arity = match &grid {
            Some(_) => Some((3, 3)),
            None => arity(f),
        };
        let Some((min_args, max_args)) = arity else {
            let mut d = Diagnostic::error(name.span, format!("unknown function `{f}`"));
            let mut names: Vec<&str> = FUNCTION_NAMES.to_vec();
            names.extend(self.options.grids.iter().map(|g| g.name()));
            if let Some(best) = suggest(f, &names) {
                d = d.with_hint(format!("did you mean `{best}`?"));
            } else {
                d = d.with_hint("see the list of functions in the documentation of fdsl");
            }
            return self.fail(d);
        };
        if args.len() < min_args || args.len() > max_args {
            let expected = if min_args == max_args {
                format!("{min_args}")
            } else if max_args == MAX_CALL_ARGS {
                format!("at least {min_args}")
            } else {
                format!("{min_args} to {max_args}")
            };
            let plural = if expected == "1" { "" } else { "s" };
            return self.fail(Diagnostic::error(
                span,
                format!(
                    "`{f}` takes {expected} argument{plural}, but {} were given",
                    args.len()
                ),
            ));
        }
        Ok(grid)
    }

    fn builtin(&mut self, f: &str, n: &[Node], span: Span) -> LResult<Node> {
        let unary = |s: &mut Self, op| s.unary(span, op, n[0]);
        match f {
            "sin" => unary(self, UnaryOp::Sin),
            "cos" => unary(self, UnaryOp::Cos),
            "tan" => unary(self, UnaryOp::Tan),
            "asin" => unary(self, UnaryOp::Asin),
            "acos" => unary(self, UnaryOp::Acos),
            "atan" => unary(self, UnaryOp::Atan),
            "sqrt" => unary(self, UnaryOp::Sqrt),
            "abs" => unary(self, UnaryOp::Abs),
            "exp" => unary(self, UnaryOp::Exp),
            "log" | "ln" => unary(self, UnaryOp::Ln),
            "floor" => unary(self, UnaryOp::Floor),
            "ceil" => unary(self, UnaryOp::Ceil),
            "sign" => unary(self, UnaryOp::Sign),
            "sqr" => unary(self, UnaryOp::Square),
            "log10" => {
                let ln = unary(self, UnaryOp::Ln)?;
                let k = self.constant(span, std::f64::consts::LOG10_E)?;
                self.binary(span, BinaryOp::Mul, ln, k)
            }
            "round" => {
                let half = self.constant(span, 0.5)?;
                let shifted = self.binary(span, BinaryOp::Add, n[0], half)?;
                self.unary(span, UnaryOp::Floor, shifted)
            }
            "sinh" | "cosh" | "tanh" => self.hyperbolic(f, n[0], span),
            "atan2" => self.binary(span, BinaryOp::Atan2, n[0], n[1]),
            "pow" => self.binary(span, BinaryOp::Pow, n[0], n[1]),
            "mod" => self.binary(span, BinaryOp::Mod, n[0], n[1]),
            "step" => self.binary(span, BinaryOp::Le, n[0], n[1]),
            "min" | "max" => {
                let op = if f == "min" {
                    BinaryOp::Min
                } else {
                    BinaryOp::Max
                };
                let mut acc = n[0];
                for &next in &n[1..] {
                    acc = self.binary(span, op, acc, next)?;
                }
                Ok(acc)
            }
            "clamp" => {
                let lo = self.binary(span, BinaryOp::Max, n[0], n[1])?;
                self.binary(span, BinaryOp::Min, lo, n[2])
            }
            "r_and" => self.binary(span, BinaryOp::RAnd, n[0], n[1]),
            "r_or" => self.binary(span, BinaryOp::ROr, n[0], n[1]),
            "r_sub" => {
                let nb = self.unary(span, UnaryOp::Neg, n[1])?;
                self.binary(span, BinaryOp::RAnd, n[0], nb)
            }
            "blend_and" => self.ternary(span, TernaryOp::BlendMin, n[0], n[1], n[2]),
            "blend_or" => self.ternary(span, TernaryOp::BlendMax, n[0], n[1], n[2]),
            "blend_sub" => {
                let nb = self.unary(span, UnaryOp::Neg, n[1])?;
                self.ternary(span, TernaryOp::BlendMin, n[0], nb, n[2])
            }
            _ => self.fail(Diagnostic::error(
                span,
                format!("`{f}` has no implementation"),
            )),
        }
    }

    fn hyperbolic(&mut self, f: &str, a: Node, span: Span) -> LResult<Node> {
        let e = self.unary(span, UnaryOp::Exp, a)?;
        let na = self.unary(span, UnaryOp::Neg, a)?;
        let ne = self.unary(span, UnaryOp::Exp, na)?;
        let half = self.constant(span, 0.5)?;
        let sum = self.binary(span, BinaryOp::Add, e, ne)?;
        let diff = self.binary(span, BinaryOp::Sub, e, ne)?;
        match f {
            "sinh" => self.binary(span, BinaryOp::Mul, diff, half),
            "cosh" => self.binary(span, BinaryOp::Mul, sum, half),
            _ => self.binary(span, BinaryOp::Div, diff, sum),
        }
    }
}

/// The output name of a function: `frep` is the main value, `parametric_x` is `x`, and so on.
fn output_name(function: &str) -> String {
    match function {
        "frep" => "value".to_string(),
        _ => function
            .strip_prefix("parametric_")
            .unwrap_or(function)
            .to_string(),
    }
}

/// The candidate closest to `name` by edit distance, when it is close enough to be a typo.
fn suggest<'a>(name: &str, candidates: &[&'a str]) -> Option<&'a str> {
    let limit = if name.len() <= 3 { 1 } else { 2 };
    candidates
        .iter()
        .map(|c| (edit_distance(name, c), *c))
        .filter(|(d, _)| *d <= limit)
        .min()
        .map(|(_, c)| c)
}

/// Edit distance where swapping two neighbouring letters counts as one edit (`sni` -> `sin`).
fn edit_distance(a: &str, b: &str) -> usize {
    let a: Vec<char> = a.chars().take(64).collect();
    let b: Vec<char> = b.chars().take(64).collect();
    let mut d = vec![vec![0usize; b.len() + 1]; a.len() + 1];
    for (i, row) in d.iter_mut().enumerate() {
        row[0] = i;
    }
    for (j, cell) in d[0].iter_mut().enumerate() {
        *cell = j;
    }
    for i in 1..=a.len() {
        for j in 1..=b.len() {
            let cost = usize::from(a[i - 1] != b[j - 1]);
            let mut best = (d[i - 1][j] + 1)
                .min(d[i][j - 1] + 1)
                .min(d[i - 1][j - 1] + cost);
            if i > 1 && j > 1 && a[i - 1] == b[j - 2] && a[i - 2] == b[j - 1] {
                best = best.min(d[i - 2][j - 2] + 1);
            }
            d[i][j] = best;
        }
    }
    d[a.len()][b.len()]
}
