//! The f32 bulk evaluator's program: a tape's instructions fused, two or more at a time, into
//! steps.
//!
//! Over a chunk of lanes, every step reads its arguments from memory and writes its result back,
//! so on short, cheap instructions (`x - c`, `t * t`, `a + b`) the loads, stores and dispatch
//! cost more than the arithmetic. A value that only one later instruction reads can be computed
//! inside that instruction's loop instead, where it never leaves a register: `(x - c)^2`,
//! `a - b^2`, `max(m, r - d)`, `a + b * c`. Most steps fuse two operations from the few that
//! distance fields are made of. A union or intersection with a ball `max(m, r - sqrt(s))` takes
//! three, and its squared distance `s` too when only the root reads it, so that a union of
//! balls is one step a ball; a sum of squares `s + (y - c)^2` takes three. A sum of up to three
//! terms `k * u` or `(u - c)^2`, after a constant or not, is one step whatever its operations:
//! a squared distance to a point, a plane `0.9 x + 0.1 y - 0.1 z`, a sphere
//! `1 - x^2 - y^2 - z^2`. A sum that only one operation reads (`min(p, plane)`, an R-function
//! of it) runs inside that operation's loop, where a square root, if the operation has one,
//! leaves the arithmetic units time for it. An operation of coordinates and constants alone
//! (`0.1 * y`) is computed again in every reader that takes it in, even when it has several.
//! Each step computes exactly what its instructions compute in turn (the same f32 operations in
//! the same order, no fused multiply-add, rewritten only where the rewrite gives the same bits),
//! so results stay bit for bit those of the unfused tape.
//!
//! The plan also gives the evaluator its own registers: a step reads coordinates straight from
//! the caller's slices ([`Arg::Input`]) and constants from the step, and registers are
//! allocated so that no step writes a register it reads.

use crate::compile::{BinaryOp, UnaryOp};
use crate::tape::{Code, Operand, Tape};

/// Where a step's argument comes from.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) enum Arg {
    /// A register of the evaluator.
    Reg(u32),
    /// A coordinate slot: 0 to 2 are lanes of points, 3 is the time, one value for all lanes.
    Input(u8),
    /// A constant.
    Const(f32),
}

/// A unary operation that fuses.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Un {
    Neg,
    Abs,
    Sqrt,
    Square,
}

/// A binary operation that fuses as the inner (first computed) operation.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Bin {
    Add,
    Sub,
    Mul,
    Min,
    Max,
}

/// A binary operation that fuses as the outer operation, written `op(v, a)` with `v` the fused
/// inner value and `a` the step's other argument. `Add`, `Mul` and the R-functions give the
/// same bits in either order; the others have a reversed form for an inner value that was the
/// right argument.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Then {
    Add,
    Mul,
    /// `v - a`
    Sub,
    /// `a - v`
    SubFrom,
    /// `min(v, a)`
    Min,
    /// `min(a, v)`
    MinOf,
    /// `max(v, a)`
    Max,
    /// `max(a, v)`
    MaxOf,
    /// The R-function intersection `v + a - sqrt(v^2 + a^2)`.
    RAnd,
    /// The R-function union `v + a + sqrt(v^2 + a^2)`.
    ROr,
}

/// `v + a`, `v - a` or `a - v`: the outer operation of a sum of squares, or the middle one of a
/// ball's distance.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Lin {
    Add,
    Sub,
    SubFrom,
}

/// `a0 + a1` or `a0 - a1`: the difference squared in a sum of squares.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Shift {
    Plus,
    Minus,
}

/// `min(v, a)`, `min(a, v)`, `max(v, a)` or `max(a, v)`: the outer operation of a union or
/// intersection with a ball.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Pick {
    Min,
    MinOf,
    Max,
    MaxOf,
}

/// What a step computes.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) enum Kind {
    /// One tape instruction over its arguments.
    Plain(Code),
    /// `u(b(args[0], args[1]))`
    UnBin(Un, Bin),
    /// `then(u(args[0]), args[1])`
    BinUn(Then, Un),
    /// `then(b(args[0], args[1]), args[2])`
    BinBin(Then, Bin),
    /// `lin((args[0] ± args[1])^2, args[2])`: a sum of squares.
    SumSq(Lin, Shift),
    /// `pick(lin(sqrt(args[0]), args[1]), args[2])`: a union or intersection with a ball.
    RootPick(Pick, Lin),
    /// `((offset + t0) + t1) + t2` over the terms of a [`Sum`], term `j` of lanes `args[j]`.
    Sum(Sum),
    /// `then(sum, args[3])`: a [`Sum`] that only this operation reads, in its loop.
    SumThen(Sum, Then),
    /// `pick(lin(sqrt(sum), radius), args[3])`: a union or intersection with a ball whose
    /// squared distance, a [`Sum`] of squares `(u - c)^2` (each `k` is 1), only its root reads.
    SumRootPick(Sum, Pick, Lin, f32),
}

/// A sum of one to three terms, each `k * (u - c)` or `k * (u - c)^2` with `u` lanes, added
/// in order after an optional constant: a squared distance, a plane, a sphere's `1 - x^2 - y^2`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct Sum {
    pub offset: Option<f32>,
    pub terms: [Term; 3],
    /// How many of `terms` are added (1 only after an offset).
    pub n: u8,
    /// Which of the `n` terms are squares, so that the loops of the common sums (all squares,
    /// or all products) compute only their own kind of term.
    pub squares: Squares,
}

/// Which terms of a [`Sum`] are squares.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Squares {
    All,
    None,
    Some,
}

/// A term of a [`Sum`]: `k * (u - c)^2` with `square`, else `k * u` (`c` is then 0).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct Term {
    pub k: f32,
    pub c: f32,
    pub square: bool,
}

impl Term {
    /// `-term`: the same bits as the term subtracted.
    fn neg(self) -> Term {
        Term { k: -self.k, ..self }
    }
}

/// One step of the program: `out = kind(args)`; unused arguments are `Const(0.0)`. Only
/// [`Kind::SumThen`] reads a fourth.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct Step {
    pub kind: Kind,
    pub out: u32,
    pub args: [Arg; 4],
}

/// A tape's program for the bulk evaluator.
#[derive(Clone, Debug)]
pub(super) struct Plan {
    pub steps: Box<[Step]>,
    pub n_regs: usize,
    pub outputs: Box<[Arg]>,
    /// The tape planned: its grids are what [`Code::Sample`] steps index.
    pub tape: Tape,
}

impl Plan {
    /// Whether a step copies its arguments into scratch lanes first (ternary operations and
    /// grid samples).
    pub fn gathers(&self) -> bool {
        self.steps
            .iter()
            .any(|s| matches!(s.kind, Kind::Plain(Code::Ternary(_) | Code::Sample(_))))
    }

    /// Whether the first output is the register that the last step writes.
    pub fn last_writes_output(&self) -> bool {
        match (self.steps.last(), self.outputs.first()) {
            (Some(step), Some(&Arg::Reg(r))) => step.out == r,
            _ => false,
        }
    }
}

/// A value of the tape before registers: a coordinate, a constant or an instruction's result.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Val {
    Input(u8),
    Const(f32),
    Instr(u32),
}

fn un(op: UnaryOp) -> Option<Un> {
    Some(match op {
        UnaryOp::Neg => Un::Neg,
        UnaryOp::Abs => Un::Abs,
        UnaryOp::Sqrt => Un::Sqrt,
        UnaryOp::Square => Un::Square,
        _ => return None,
    })
}

fn bin(op: BinaryOp) -> Option<Bin> {
    Some(match op {
        BinaryOp::Add => Bin::Add,
        BinaryOp::Sub => Bin::Sub,
        BinaryOp::Mul => Bin::Mul,
        BinaryOp::Min => Bin::Min,
        BinaryOp::Max => Bin::Max,
        _ => return None,
    })
}

/// The outer operation `op(a, b)` with the inner value in argument `at` (0 or 1).
fn then(op: Bin, at: usize) -> Then {
    match (op, at) {
        (Bin::Add, _) => Then::Add,
        (Bin::Mul, _) => Then::Mul,
        (Bin::Sub, 0) => Then::Sub,
        (Bin::Sub, _) => Then::SubFrom,
        (Bin::Min, 0) => Then::Min,
        (Bin::Min, _) => Then::MinOf,
        (Bin::Max, 0) => Then::Max,
        (Bin::Max, _) => Then::MaxOf,
    }
}

/// The outer operation `op(a, b)`, R-functions included, with the inner value in argument `at`.
fn outer(op: BinaryOp, at: usize) -> Option<Then> {
    match op {
        BinaryOp::RAnd => Some(Then::RAnd),
        BinaryOp::ROr => Some(Then::ROr),
        op => bin(op).map(|b| then(b, at)),
    }
}

/// The outer `Add` or `Sub` of three fused operations, with the inner value in argument `at`.
fn lin(op: BinaryOp, at: usize) -> Option<Lin> {
    Some(match (op, at) {
        (BinaryOp::Add, _) => Lin::Add,
        (BinaryOp::Sub, 0) => Lin::Sub,
        (BinaryOp::Sub, _) => Lin::SubFrom,
        _ => return None,
    })
}

/// The outer `Min` or `Max` of three fused operations, with the inner value in argument `at`.
fn pick(op: BinaryOp, at: usize) -> Option<Pick> {
    Some(match (op, at) {
        (BinaryOp::Min, 0) => Pick::Min,
        (BinaryOp::Min, _) => Pick::MinOf,
        (BinaryOp::Max, 0) => Pick::Max,
        (BinaryOp::Max, _) => Pick::MaxOf,
        _ => return None,
    })
}

/// Fuses `tape`'s instructions in pairs and allocates registers for the result.
pub(super) fn plan(tape: &Tape) -> Plan {
    plan_with(tape, true)
}

/// [`plan`], or with `fusing` false one step per instruction: the reference the tests compare
/// fused steps with.
pub(super) fn plan_with(tape: &Tape, fusing: bool) -> Plan {
    let instrs = tape.instrs();
    let code = |j: usize| instrs[j].code;
    let (mut nodes, holds) = nodes_of(tape);
    for i in (0..nodes.len()).filter(|_| fusing) {
        fuse(&mut nodes, &code, i);
    }
    // Each remaining instruction becomes a step over values.
    let steps: Vec<(u32, Kind, [Val; 4])> = (0..nodes.len())
        .filter(|&i| !nodes[i].fused_away)
        .map(|i| {
            let (kind, args) = step_of(&nodes, &code, i);
            (i as u32, kind, args)
        })
        .collect();
    let (steps, n_regs) = allocate(&mut nodes, &steps);
    Plan {
        steps: steps.into(),
        n_regs,
        outputs: tape
            .outputs()
            .iter()
            .map(|&o| arg(&nodes, operand(&holds, o)))
            .collect(),
        tape: tape.clone(),
    }
}

/// The value operand `o` names, given what each register holds.
fn operand(holds: &[Val], o: Operand) -> Val {
    match o {
        Operand::Reg(r) => holds[r as usize],
        Operand::Const(c) => Val::Const(c as f32),
    }
}

/// A step's argument for value `v`, once registers are allocated.
fn arg(nodes: &[Node], v: Val) -> Arg {
    match v {
        Val::Input(slot) => Arg::Input(slot),
        Val::Const(c) => Arg::Const(c),
        Val::Instr(j) => Arg::Reg(nodes[j as usize].reg),
    }
}

/// The tape's register program back to values: one node per instruction with its arguments
/// and readers counted, and what each register holds at the end.
fn nodes_of(tape: &Tape) -> (Vec<Node>, Vec<Val>) {
    let instrs = tape.instrs();
    let mut holds = vec![Val::Const(0.0); tape.n_regs()];
    for (slot, reg) in tape.inputs().iter().enumerate() {
        if let Some(r) = reg {
            holds[*r as usize] = Val::Input(slot as u8);
        }
    }
    let mut nodes: Vec<Node> = Vec::with_capacity(instrs.len());
    for (i, instr) in instrs.iter().enumerate() {
        let mut args = [Val::Const(0.0); 3];
        for (k, slot) in args.iter_mut().enumerate().take(instr.code.n_args()) {
            *slot = operand(&holds, instr.args[k]);
            if let Val::Instr(j) = *slot {
                nodes[j as usize].uses += 1;
            }
        }
        nodes.push(Node::new(args));
        holds[instr.out as usize] = Val::Instr(i as u32);
    }
    for &o in tape.outputs() {
        if let Val::Instr(j) = operand(&holds, o) {
            // An output is read after the last step: never fused into a reader, nor freed.
            nodes[j as usize].uses += 2;
            nodes[j as usize].last_read = u32::MAX;
        }
    }
    (nodes, holds)
}

/// Picks what instruction `i` takes into its step; pairs are picked in tape order.
///
/// `inner` is the instruction fused into a node; an instruction that took one in, or was
/// taken in, takes part in no other pair, except that a pair of the two idioms of distance
/// fields is taken into a third instruction (`deep`): a sum of squares `s + (y - c)^2`, and a
/// union or intersection with a ball `max(m, r - sqrt(s))`.
///
/// A cheap operation of coordinates and constants alone (`0.1 * y`) is computed again inside
/// each reader that takes it in, rather than stored once for several: an operation costs less
/// than a step. It stays a step of its own only for readers that did not.
fn fuse(nodes: &mut [Node], code: &impl Fn(usize) -> Code, i: usize) {
    if let Some((sum, absorbed)) = sum_of(nodes, code, i) {
        nodes[i].sum = Some(sum);
        for j in absorbed.into_iter().flatten() {
            let node = &mut nodes[j];
            node.taken += 1;
            node.fused_away = node.taken == node.uses;
        }
        return;
    }
    if take_sum(nodes, code, i) {
        return;
    }
    let (candidates, op): (&[usize], _) = match code(i) {
        Code::Unary(op) if un(op).is_some() => (&[0], None),
        Code::Binary(op) if bin(op).is_some() => (&[1, 0], Some(op)),
        _ => return,
    };
    if !take_triple(nodes, code, i, candidates, op) {
        take_pair(nodes, code, i, candidates);
    }
}

/// Takes into operation `i` a sum that only it reads, to compute the sum in its loop.
fn take_sum(nodes: &mut [Node], code: &impl Fn(usize) -> Code, i: usize) -> bool {
    let Code::Binary(op) = code(i) else {
        return false;
    };
    if outer(op, 0).is_none() {
        return false;
    }
    let sum = [1, 0].into_iter().find_map(|at| match nodes[i].args[at] {
        Val::Instr(j) => {
            let node = &nodes[j as usize];
            let alone = node.uses == 1 && !node.fused_away;
            (node.sum.is_some() && alone).then_some(j)
        }
        _ => None,
    });
    let Some(j) = sum else {
        return false;
    };
    nodes[i].inner = Some(j);
    nodes[j as usize].fused_away = true;
    true
}

/// Takes into `i` a pair of one of the two idioms of distance fields (a sum of squares, a
/// union or intersection with a ball), and the ball's sum of squares too when it can.
fn take_triple(
    nodes: &mut [Node],
    code: &impl Fn(usize) -> Code,
    i: usize,
    candidates: &[usize],
    op: Option<BinaryOp>,
) -> bool {
    let (square, sqrt) = (Code::Unary(UnaryOp::Square), Code::Unary(UnaryOp::Sqrt));
    let is_sum = |c: Code| matches!(c, Code::Binary(BinaryOp::Add | BinaryOp::Sub));
    let triple = candidates.iter().find_map(|&at| {
        let Val::Instr(j) = nodes[i].args[at] else {
            return None;
        };
        let inner = &nodes[j as usize];
        let k = inner.inner.filter(|_| inner.uses == 1 && !inner.deep)?;
        let (cj, ck) = (code(j as usize), code(k as usize));
        let fits = match op? {
            BinaryOp::Add | BinaryOp::Sub => cj == square && is_sum(ck),
            BinaryOp::Min | BinaryOp::Max => is_sum(cj) && ck == sqrt,
            _ => false,
        };
        fits.then_some(j as usize)
    });
    let Some(j) = triple else {
        return false;
    };
    nodes[i].inner = Some(j as u32);
    nodes[i].deep = true;
    nodes[j].fused_away = true;
    if let Some((s, radius)) = ball_sum(nodes, code, j) {
        nodes[i].ball_radius = Some(radius);
        nodes[s].fused_away = true;
    }
    true
}

/// Takes into `i` the first of its arguments (in `candidates` order) that a simple pair can
/// compute in one loop.
fn take_pair(nodes: &mut [Node], code: &impl Fn(usize) -> Code, i: usize, candidates: &[usize]) {
    let leafy = |node: &Node, j: usize| {
        let k = code(j).n_args();
        node.args[..k].iter().all(|v| !matches!(v, Val::Instr(_)))
    };
    let simple_args = |a: &[Val; 3], k: usize| {
        // A time argument is one value, not lanes, and two constants would have been folded:
        // the fused loops take neither.
        !a[..k].contains(&Val::Input(3)) && a[..k].iter().any(|v| !matches!(v, Val::Const(_)))
    };
    for &at in candidates {
        let Val::Instr(j) = nodes[i].args[at] else {
            continue;
        };
        let j = j as usize;
        let inner = &nodes[j];
        let takes = inner.inner.is_none()
            && inner.sum.is_none()
            && !inner.fused_away
            && (inner.uses == 1 || leafy(inner, j))
            && match (code(i), code(j)) {
                (Code::Unary(_), Code::Binary(b)) => bin(b).is_some(),
                (Code::Binary(_), Code::Unary(u)) => un(u).is_some(),
                (Code::Binary(_), Code::Binary(b)) => bin(b).is_some(),
                _ => false,
            }
            && simple_args(&inner.args, code(j).n_args());
        if takes {
            nodes[i].inner = Some(j as u32);
            let inner = &mut nodes[j];
            inner.taken += 1;
            inner.fused_away = inner.taken == inner.uses;
            break;
        }
    }
}

/// `[a, b, c]` as a step's four arguments, the fourth unused.
fn three([a, b, c]: [Val; 3]) -> [Val; 4] {
    [a, b, c, Val::Const(0.0)]
}

/// The step of instruction `i` (not fused away) over values: what it computes and its
/// arguments.
fn step_of(nodes: &[Node], code: &impl Fn(usize) -> Code, i: usize) -> (Kind, [Val; 4]) {
    let node = &nodes[i];
    let args = node.args;
    if let Some(p) = node.sum {
        let (sum, [u0, u1, u2]) = p.split();
        return (Kind::Sum(sum), [u0, u1, u2, Val::Const(0.0)]);
    }
    match (code(i), node.inner) {
        (code, None) => (Kind::Plain(code), three(args)),
        (Code::Binary(op), Some(j)) if nodes[j as usize].sum.is_some() => {
            let at = usize::from(args[1] == Val::Instr(j));
            let then = outer(op, at).expect("only simple operations take a sum in");
            let Some(p) = nodes[j as usize].sum else {
                unreachable!("the guard found a sum")
            };
            let (sum, [u0, u1, u2]) = p.split();
            (Kind::SumThen(sum, then), [u0, u1, u2, args[1 - at]])
        }
        (Code::Binary(op), Some(j)) if node.deep => deep_step(nodes, code, i, op, j as usize),
        (Code::Unary(u), Some(j)) => {
            let (Some(u), Code::Binary(b)) = (un(u), code(j as usize)) else {
                unreachable!("only simple pairs were picked")
            };
            let b = bin(b).expect("only simple pairs were picked");
            (Kind::UnBin(u, b), three(nodes[j as usize].args))
        }
        (Code::Binary(op), Some(j)) => {
            let at = usize::from(args[1] == Val::Instr(j));
            let other = args[1 - at];
            let outer = then(bin(op).expect("only simple pairs were picked"), at);
            let inner = nodes[j as usize].args;
            match code(j as usize) {
                Code::Unary(u) => {
                    let u = un(u).expect("only simple pairs were picked");
                    (
                        Kind::BinUn(outer, u),
                        three([inner[0], other, Val::Const(0.0)]),
                    )
                }
                Code::Binary(b) => {
                    let b = bin(b).expect("only simple pairs were picked");
                    (Kind::BinBin(outer, b), three([inner[0], inner[1], other]))
                }
                _ => unreachable!("only simple pairs were picked"),
            }
        }
        _ => unreachable!("only unary and binary instructions take a pair"),
    }
}

/// The step of operation `i` (`op`), which took in the pair `j` of a distance-field idiom: a
/// sum of squares, or a union or intersection with a ball (its sum of squares too, maybe).
fn deep_step(
    nodes: &[Node],
    code: &impl Fn(usize) -> Code,
    i: usize,
    op: BinaryOp,
    j: usize,
) -> (Kind, [Val; 4]) {
    let node = &nodes[i];
    let at = usize::from(node.args[1] == Val::Instr(j as u32));
    let other = node.args[1 - at];
    let k = nodes[j].inner.expect("a triple takes in a pair") as usize;
    let (middle, innermost) = (&nodes[j].args, &nodes[k].args);
    match (code(j), code(k)) {
        (Code::Unary(_), Code::Binary(b)) => {
            let outer = lin(op, at).expect("a sum of squares adds");
            let shift = match b {
                BinaryOp::Add => Shift::Plus,
                _ => Shift::Minus,
            };
            let args = [innermost[0], innermost[1], other];
            (Kind::SumSq(outer, shift), three(args))
        }
        (Code::Binary(m), _) => {
            let outer = pick(op, at).expect("a ball is picked by min or max");
            let at_root = usize::from(middle[1] == Val::Instr(k as u32));
            let m = lin(m, at_root).expect("a ball's radius is added");
            match (node.ball_radius, innermost[0]) {
                (Some(radius), Val::Instr(s)) => {
                    let Some(p) = nodes[s as usize].sum else {
                        unreachable!("a ball's sum was planned as one")
                    };
                    let (sum, [u0, u1, u2]) = p.split();
                    let kind = Kind::SumRootPick(sum, outer, m, radius);
                    (kind, [u0, u1, u2, other])
                }
                (Some(_), _) => unreachable!("a ball's sum is an instruction"),
                (None, root) => {
                    let args = [root, middle[1 - at_root], other];
                    (Kind::RootPick(outer, m), three(args))
                }
            }
        }
        _ => unreachable!("only the two idioms were picked"),
    }
}

/// Registers for `steps` (instruction, kind, arguments), allocated as the tape does: a step's
/// output before its arguments are freed, so that it never overwrites them. Returns the steps
/// over registers and how many registers there are.
fn allocate(nodes: &mut [Node], steps: &[(u32, Kind, [Val; 4])]) -> (Vec<Step>, usize) {
    for (s, (_, _, a)) in steps.iter().enumerate() {
        for v in a {
            if let Val::Instr(j) = *v
                && nodes[j as usize].last_read != u32::MAX
            {
                nodes[j as usize].last_read = s as u32;
            }
        }
    }
    let mut free: Vec<u32> = Vec::new();
    let mut n_regs = 0u32;
    let mut out_steps = Vec::with_capacity(steps.len());
    for (s, &(i, kind, a)) in steps.iter().enumerate() {
        let args = a.map(|v| arg(nodes, v));
        let out = free.pop().unwrap_or_else(|| {
            n_regs += 1;
            n_regs - 1
        });
        nodes[i as usize].reg = out;
        for (k, v) in a.iter().enumerate() {
            if let Val::Instr(j) = *v
                && nodes[j as usize].last_read == s as u32
                && !a[..k].contains(v)
            {
                free.push(nodes[j as usize].reg);
            }
        }
        out_steps.push(Step { kind, out, args });
    }
    (out_steps, n_regs as usize)
}

/// A [`Sum`] before registers: its terms' lanes are values.
#[derive(Clone, Copy, Debug)]
struct Planned {
    offset: Option<f32>,
    terms: [(Val, Term); 3],
    n: u8,
}

impl Planned {
    /// The step's sum, and the lanes of its terms.
    fn split(self) -> (Sum, [Val; 3]) {
        let used = &self.terms[..usize::from(self.n)];
        let squares = match used.iter().filter(|(_, t)| t.square).count() {
            0 => Squares::None,
            k if k == used.len() => Squares::All,
            _ => Squares::Some,
        };
        let sum = Sum {
            offset: self.offset,
            terms: self.terms.map(|(_, t)| t),
            n: self.n,
            squares,
        };
        (sum, self.terms.map(|(u, _)| u))
    }

    /// The sum with `term` added last, when it has room.
    fn then(self, term: (Val, Term)) -> Option<Planned> {
        let mut next = self;
        *next.terms.get_mut(usize::from(self.n))? = term;
        next.n += 1;
        Some(next)
    }
}

/// What an argument of a sum is to it.
enum Part {
    /// A term it computes again in its own step, and the instruction that gave it.
    Term(usize, (Val, Term)),
    /// A smaller sum, which only this sum reads.
    Sum(usize, Planned),
    Const(f32),
}

/// Instruction `i` as a [`Sum`] of the terms and sums it reads, and the instructions it takes
/// in.
///
/// Every rewrite gives the tape's bits: addition gives the same bits in either order,
/// `a - b` is `a + (-b)`, `-(k * v)` is `(-k) * v`, `(c - u)^2` is `(u - c)^2` (rounding to
/// nearest is symmetric), `(u + c)^2` is `(u - (-c))^2`, and `u` is `u - 0` and `1 * u`.
fn sum_of(
    nodes: &[Node],
    code: &impl Fn(usize) -> Code,
    i: usize,
) -> Option<(Planned, [Option<usize>; 2])> {
    let minus = match code(i) {
        Code::Binary(BinaryOp::Add) => false,
        Code::Binary(BinaryOp::Sub) => true,
        _ => return None,
    };
    let part = |v: Val| match v {
        Val::Const(c) => Some(Part::Const(c)),
        Val::Input(_) => None,
        Val::Instr(j) => {
            let j = j as usize;
            let node = &nodes[j];
            match node.sum {
                Some(s) if node.uses == 1 && !node.fused_away => Some(Part::Sum(j, s)),
                Some(_) => None,
                None => term(nodes, code, j).map(|t| Part::Term(j, t)),
            }
        }
    };
    let signed = |t: (Val, Term)| if minus { (t.0, t.1.neg()) } else { t };
    let blank = (
        Val::Const(0.0),
        Term {
            k: 0.0,
            c: 0.0,
            square: false,
        },
    );
    let sum = |offset, terms: &[(Val, Term)]| {
        let mut all = [blank; 3];
        all[..terms.len()].copy_from_slice(terms);
        Planned {
            offset,
            terms: all,
            n: terms.len() as u8,
        }
    };
    let [a, b, _] = nodes[i].args;
    Some(match (part(a)?, part(b)?) {
        (Part::Sum(j, s), Part::Term(l, t)) => (s.then(signed(t))?, [Some(j), Some(l)]),
        // `t - s` is not `(-s) + t`: negating a sum of zeros of both signs gives `-0`, the
        // negated terms' sum `+0`.
        (Part::Term(l, t), Part::Sum(j, s)) if !minus => (s.then(t)?, [Some(j), Some(l)]),
        (Part::Term(j, t), Part::Term(l, u)) => (sum(None, &[t, signed(u)]), [Some(j), Some(l)]),
        (Part::Const(c), Part::Term(l, t)) => (sum(Some(c), &[signed(t)]), [Some(l), None]),
        (Part::Term(l, t), Part::Const(c)) => {
            (sum(Some(if minus { -c } else { c }), &[t]), [Some(l), None])
        }
        _ => return None,
    })
}

/// The sum of squares under the root of ball `j` (`r - sqrt(s)` or `sqrt(s) - r`, its root
/// fused in), and the radius, when only that root reads the sum, each of its terms is a square
/// `(u - c)^2` taken once, and the radius is a constant: the squared distance that a union or
/// intersection with the ball can compute in its own loop.
fn ball_sum(nodes: &[Node], code: &impl Fn(usize) -> Code, j: usize) -> Option<(usize, f32)> {
    let root = nodes[j].inner?;
    let radius = nodes[j].args[..code(j).n_args()]
        .iter()
        .find_map(|v| match *v {
            Val::Const(r) => Some(r),
            _ => None,
        })?;
    let Val::Instr(s) = nodes[root as usize].args[0] else {
        return None;
    };
    let node = &nodes[s as usize];
    let sum = node.sum?;
    let distance = sum.terms[..usize::from(sum.n)]
        .iter()
        .all(|(_, t)| t.square && t.k == 1.0);
    (distance && node.uses == 1 && !node.fused_away).then_some((s as usize, radius))
}

/// Instruction `j` as a term `k * (u - c)^2` or `k * u` with `u` lanes, when no other reader
/// needs it stored: a square of a difference with a constant, or a product with one.
fn term(nodes: &[Node], code: &impl Fn(usize) -> Code, j: usize) -> Option<(Val, Term)> {
    let node = &nodes[j];
    let leafy = node.args[..code(j).n_args()]
        .iter()
        .all(|v| !matches!(v, Val::Instr(_)));
    if node.fused_away || !(node.uses == 1 || leafy) {
        return None;
    }
    let (u, term) = match (code(j), node.inner) {
        (Code::Unary(UnaryOp::Square), None) => (node.args[0], (1.0, 0.0)),
        (Code::Unary(UnaryOp::Square), Some(k)) => {
            let diff = &nodes[k as usize];
            if diff.inner.is_some() {
                return None;
            }
            let (u, c) = match (code(k as usize), diff.args[0], diff.args[1]) {
                (Code::Binary(BinaryOp::Sub), u, Val::Const(c))
                | (Code::Binary(BinaryOp::Sub), Val::Const(c), u) => (u, c),
                (Code::Binary(BinaryOp::Add), u, Val::Const(c))
                | (Code::Binary(BinaryOp::Add), Val::Const(c), u) => (u, -c),
                _ => return None,
            };
            (u, (1.0, c))
        }
        (Code::Binary(BinaryOp::Mul), None) => match (node.args[0], node.args[1]) {
            (u, Val::Const(k)) | (Val::Const(k), u) => (u, (k, 0.0)),
            _ => return None,
        },
        _ => return None,
    };
    let square = code(j) == Code::Unary(UnaryOp::Square);
    let lanes = matches!(u, Val::Input(0..=2) | Val::Instr(_));
    lanes.then_some((
        u,
        Term {
            k: term.0,
            c: term.1,
            square,
        },
    ))
}

/// What planning knows of one instruction of the tape.
#[derive(Clone, Copy, Debug)]
struct Node {
    args: [Val; 3],
    /// Readers, an output counting two.
    uses: u32,
    /// Readers that took it into their step.
    taken: u32,
    /// The instruction this one took into its step.
    inner: Option<u32>,
    /// Whether `inner` is itself a pair.
    deep: bool,
    /// When `inner` is a ball's root and constant radius and the root's [`Sum`] of squares is
    /// computed in this step too: that radius.
    ball_radius: Option<f32>,
    /// What it adds, when it is a [`Sum`] of terms.
    sum: Option<Planned>,
    /// Whether every reader took it in, so that it is no step of its own.
    fused_away: bool,
    /// The last step that reads it (`u32::MAX`: an output, read after every step).
    last_read: u32,
    /// Its register.
    reg: u32,
}

impl Node {
    fn new(args: [Val; 3]) -> Node {
        Node {
            args,
            uses: 0,
            taken: 0,
            inner: None,
            deep: false,
            ball_radius: None,
            sum: None,
            fused_away: false,
            last_read: 0,
            reg: u32::MAX,
        }
    }
}
