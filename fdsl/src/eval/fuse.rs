//! The f32 bulk evaluator's program: a tape's instructions with pairs, and a few triples, fused
//! into one step.
//!
//! Over a chunk of lanes, every step reads its arguments from memory and writes its result back,
//! so on short, cheap instructions (`x - c`, `t * t`, `a + b`) the loads, stores and dispatch
//! cost more than the arithmetic. A value that only one later instruction reads can be computed
//! inside that instruction's loop instead, where it never leaves a register: `(x - c)^2`,
//! `a - b^2`, `max(m, r - d)`, `a + b * c`. Most steps fuse two operations from the few that
//! distance fields are made of; the two idioms of a ball take three, a sum of squares
//! `s + (y - c)^2` and a union or intersection with a ball `max(m, r - sqrt(s))`. An operation
//! of coordinates and constants alone (`0.1 * y`) is computed again in every reader that takes
//! it in, even when it has several. Each step computes exactly what its instructions compute in
//! turn (the same f32 operations in the same order, no fused multiply-add), so results stay bit
//! for bit those of the unfused tape.
//!
//! The plan also gives the evaluator its own registers: a step reads coordinates straight from
//! the caller's slices ([`Arg::Input`]) and constants from the step, and registers are
//! allocated so that no step writes a register it reads.

use std::sync::Arc;

use crate::compile::{BinaryOp, UnaryOp};
use crate::grid::Grid;
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
/// inner value and `a` the step's other argument. `Add` and `Mul` give the same bits in either
/// order; the others have a reversed form for an inner value that was the right argument.
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
}

/// One step of the program: `out = kind(args)`; unused arguments are `Const(0.0)`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct Step {
    pub kind: Kind,
    pub out: u32,
    pub args: [Arg; 3],
}

/// A tape's program for the bulk evaluator.
#[derive(Clone, Debug)]
pub(super) struct Plan {
    pub steps: Box<[Step]>,
    pub n_regs: usize,
    pub outputs: Box<[Arg]>,
    /// The grids that [`Code::Sample`] steps index.
    pub grids: Box<[Arc<Grid>]>,
}

impl Plan {
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

fn n_args(code: Code) -> usize {
    match code {
        Code::Unary(_) => 1,
        Code::Binary(_) => 2,
        Code::Ternary(_) | Code::Sample(_) => 3,
    }
}

/// Fuses `tape`'s instructions in pairs and allocates registers for the result.
pub(super) fn plan(tape: &Tape) -> Plan {
    plan_with(tape, true)
}

/// [`plan`], or with `fusing` false one step per instruction: the reference the tests compare
/// fused steps with.
pub(super) fn plan_with(tape: &Tape, fusing: bool) -> Plan {
    let instrs = tape.instrs();
    let n = instrs.len();
    // The tape's register program back to values: what each register holds as it runs.
    let mut holds = vec![Val::Const(0.0); tape.n_regs()];
    for (slot, reg) in tape.inputs().iter().enumerate() {
        if let Some(r) = reg {
            holds[*r as usize] = Val::Input(slot as u8);
        }
    }
    let operand = |holds: &[Val], o: Operand| match o {
        Operand::Reg(r) => holds[r as usize],
        Operand::Const(c) => Val::Const(c as f32),
    };
    let mut args = Vec::with_capacity(n);
    let mut uses = vec![0u32; n];
    for (i, instr) in instrs.iter().enumerate() {
        let mut a = [Val::Const(0.0); 3];
        for (k, slot) in a.iter_mut().enumerate().take(n_args(instr.code)) {
            *slot = operand(&holds, instr.args[k]);
            if let Val::Instr(j) = *slot {
                uses[j as usize] += 1;
            }
        }
        args.push(a);
        holds[instr.out as usize] = Val::Instr(i as u32);
    }
    let outputs: Vec<Val> = tape.outputs().iter().map(|&o| operand(&holds, o)).collect();
    for o in &outputs {
        if let Val::Instr(j) = *o {
            // An output is read after the last step: never fused into a reader.
            uses[j as usize] += 2;
        }
    }

    // Pick pairs in order. `inner[i]` is the instruction fused into `i`; an instruction that
    // took one in, or was taken in, takes part in no other pair, except that a pair of the two
    // idioms of distance fields is taken into a third instruction (`deep`): a sum of squares
    // `s + (y - c)^2`, and a union or intersection with a ball `max(m, r - sqrt(s))`.
    let mut inner: Vec<Option<u32>> = vec![None; n];
    let mut deep = vec![false; n];
    let mut fused_away = vec![false; n];
    // A cheap operation of coordinates and constants alone (`0.1 * y`) is computed again
    // inside each reader that takes it in, rather than stored once for several: an operation
    // costs less than a step. It stays a step of its own only for readers that did not.
    let leafy = |j: usize| {
        let k = n_args(instrs[j].code);
        args[j][..k].iter().all(|v| !matches!(v, Val::Instr(_)))
    };
    let mut taken = vec![0u32; n];
    let code = |j: usize| instrs[j].code;
    let is_pair = |inner: &[Option<u32>], deep: &[bool], j: usize, outer: Code, in_: Code| {
        !deep[j] && code(j) == outer && inner[j].is_some_and(|k| code(k as usize) == in_)
    };
    let simple_args = |a: &[Val; 3], k: usize| {
        // A time argument is one value, not lanes, and two constants would have been folded:
        // the fused loops take neither.
        !a[..k].contains(&Val::Input(3)) && a[..k].iter().any(|v| !matches!(v, Val::Const(_)))
    };
    for i in (0..n).filter(|_| fusing) {
        let candidates: &[usize] = match instrs[i].code {
            Code::Unary(op) if un(op).is_some() => &[0],
            Code::Binary(op) if bin(op).is_some() => &[1, 0],
            _ => &[],
        };
        let triple = candidates.iter().find_map(|&at| {
            let Val::Instr(j) = args[i][at] else {
                return None;
            };
            let j = j as usize;
            let Code::Binary(op) = code(i) else {
                return None;
            };
            let square = Code::Unary(UnaryOp::Square);
            let sqrt = Code::Unary(UnaryOp::Sqrt);
            let sum = |b| Code::Binary(b);
            let fits = uses[j] == 1
                && match op {
                    BinaryOp::Add | BinaryOp::Sub => [BinaryOp::Add, BinaryOp::Sub]
                        .into_iter()
                        .any(|b| is_pair(&inner, &deep, j, square, sum(b))),
                    BinaryOp::Min | BinaryOp::Max => [BinaryOp::Add, BinaryOp::Sub]
                        .into_iter()
                        .any(|b| is_pair(&inner, &deep, j, sum(b), sqrt)),
                    _ => false,
                };
            fits.then_some(j)
        });
        if let Some(j) = triple {
            inner[i] = Some(j as u32);
            deep[i] = true;
            fused_away[j] = true;
            continue;
        }
        for &at in candidates {
            let Val::Instr(j) = args[i][at] else { continue };
            let j = j as usize;
            let takes = (uses[j] == 1 || leafy(j))
                && inner[j].is_none()
                && !fused_away[j]
                && simple_args(&args[j], n_args(instrs[j].code))
                && match (instrs[i].code, instrs[j].code) {
                    (Code::Unary(_), Code::Binary(b)) => bin(b).is_some(),
                    (Code::Binary(_), Code::Unary(u)) => un(u).is_some(),
                    (Code::Binary(_), Code::Binary(b)) => bin(b).is_some(),
                    _ => false,
                };
            if takes {
                inner[i] = Some(j as u32);
                taken[j] += 1;
                fused_away[j] = taken[j] == uses[j];
                break;
            }
        }
    }

    // Each remaining instruction becomes a step over values; then registers, allocated as the
    // tape does: a step's output before its arguments are freed, so it never overwrites them.
    let mut steps: Vec<(usize, Kind, [Val; 3])> = Vec::with_capacity(n);
    for i in 0..n {
        if fused_away[i] {
            continue;
        }
        let code = code(i);
        let step = match (code, inner[i]) {
            (_, None) => (i, Kind::Plain(code), args[i]),
            (Code::Binary(op), Some(j)) if deep[i] => {
                let j = j as usize;
                let at = usize::from(args[i][1] == Val::Instr(j as u32));
                let other = args[i][1 - at];
                let k = inner[j].expect("a triple takes in a pair") as usize;
                match (instrs[j].code, instrs[k].code) {
                    (Code::Unary(_), Code::Binary(b)) => {
                        let outer = lin(op, at).expect("a sum of squares adds");
                        let shift = match b {
                            BinaryOp::Add => Shift::Plus,
                            _ => Shift::Minus,
                        };
                        (
                            i,
                            Kind::SumSq(outer, shift),
                            [args[k][0], args[k][1], other],
                        )
                    }
                    (Code::Binary(middle), _) => {
                        let outer = pick(op, at).expect("a ball is picked by min or max");
                        let at_root = usize::from(args[j][1] == Val::Instr(k as u32));
                        let middle = lin(middle, at_root).expect("a ball's radius is added");
                        let radius = args[j][1 - at_root];
                        (
                            i,
                            Kind::RootPick(outer, middle),
                            [args[k][0], radius, other],
                        )
                    }
                    _ => unreachable!("only the two idioms were picked"),
                }
            }
            (Code::Unary(u), Some(j)) => {
                let (Some(u), Code::Binary(b)) = (un(u), instrs[j as usize].code) else {
                    unreachable!("only simple pairs were picked")
                };
                let b = bin(b).expect("only simple pairs were picked");
                (i, Kind::UnBin(u, b), args[j as usize])
            }
            (Code::Binary(op), Some(j)) => {
                let at = usize::from(args[i][1] == Val::Instr(j));
                let other = args[i][1 - at];
                let outer = then(bin(op).expect("only simple pairs were picked"), at);
                let inner_args = args[j as usize];
                match instrs[j as usize].code {
                    Code::Unary(u) => {
                        let u = un(u).expect("only simple pairs were picked");
                        (
                            i,
                            Kind::BinUn(outer, u),
                            [inner_args[0], other, Val::Const(0.0)],
                        )
                    }
                    Code::Binary(b) => {
                        let b = bin(b).expect("only simple pairs were picked");
                        (
                            i,
                            Kind::BinBin(outer, b),
                            [inner_args[0], inner_args[1], other],
                        )
                    }
                    _ => unreachable!("only simple pairs were picked"),
                }
            }
            _ => unreachable!("only unary and binary instructions take a pair"),
        };
        steps.push(step);
    }

    let mut last_read = vec![0usize; n];
    for (s, (_, _, a)) in steps.iter().enumerate() {
        for v in a {
            if let Val::Instr(j) = *v {
                last_read[j as usize] = s;
            }
        }
    }
    for o in &outputs {
        if let Val::Instr(j) = *o {
            last_read[j as usize] = usize::MAX;
        }
    }
    let mut reg_of = vec![u32::MAX; n];
    let mut free: Vec<u32> = Vec::new();
    let mut n_regs = 0u32;
    let arg = |reg_of: &[u32], v: Val| match v {
        Val::Input(slot) => Arg::Input(slot),
        Val::Const(c) => Arg::Const(c),
        Val::Instr(j) => Arg::Reg(reg_of[j as usize]),
    };
    let mut out_steps = Vec::with_capacity(steps.len());
    for (s, &(i, kind, a)) in steps.iter().enumerate() {
        let args = [arg(&reg_of, a[0]), arg(&reg_of, a[1]), arg(&reg_of, a[2])];
        let out = free.pop().unwrap_or_else(|| {
            n_regs += 1;
            n_regs - 1
        });
        reg_of[i] = out;
        for (k, v) in a.iter().enumerate() {
            if let Val::Instr(j) = *v
                && last_read[j as usize] == s
                && !a[..k].contains(v)
            {
                free.push(reg_of[j as usize]);
            }
        }
        out_steps.push(Step { kind, out, args });
    }
    Plan {
        steps: out_steps.into(),
        n_regs: n_regs as usize,
        outputs: outputs.iter().map(|&v| arg(&reg_of, v)).collect(),
        grids: tape.grids().into(),
    }
}
