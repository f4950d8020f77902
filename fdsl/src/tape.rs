//! Tapes: a straight-line program of register instructions scheduled from the graph, and
//! simplification of a tape from the choices an interval evaluation made over a region.
//!
//! A tape keeps two forms: an SSA list (each operation's result has its own index, used for
//! simplification) and a register program (used by the evaluators), where registers are reused
//! once a value is dead, so the evaluators touch little memory.

use std::sync::Arc;

use crate::compile::graph::{Context, Node, Op};
use crate::compile::ops::{BinaryOp, TernaryOp, UnaryOp};
use crate::grid::Grid;

/// What an instruction computes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Code {
    /// One argument.
    Unary(UnaryOp),
    /// Two arguments.
    Binary(BinaryOp),
    /// Three arguments.
    Ternary(TernaryOp),
    /// The grid of this index in [`Tape::grids`] at the three arguments `(x, y, z)`.
    Sample(u8),
}

/// An instruction's argument: a register, or a constant folded into the instruction.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Operand {
    /// The value in a register.
    Reg(u32),
    /// A constant.
    Const(f64),
}

impl Code {
    /// How many of an instruction's arguments this operation reads.
    pub fn n_args(self) -> usize {
        match self {
            Code::Unary(_) => 1,
            Code::Binary(_) => 2,
            Code::Ternary(_) | Code::Sample(_) => 3,
        }
    }
}

/// One register instruction: `out = code(args)`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Instr {
    /// The operation.
    pub code: Code,
    /// The register written.
    pub out: u32,
    /// The arguments (unused ones are `Const(0.0)`).
    pub args: [Operand; 3],
}

impl Instr {
    /// Whether an interval evaluation may choose one argument of this instruction over a region.
    pub fn has_choice(&self) -> bool {
        matches!(
            self.code,
            Code::Binary(BinaryOp::Min | BinaryOp::Max | BinaryOp::RAnd | BinaryOp::ROr)
                | Code::Ternary(_)
        )
    }
}

/// What an interval evaluation learnt about one instruction over a region.
///
/// `Left`/`Right` name the argument that decides the result: the first or second argument of
/// `min`/`max`/R-functions/blends, and the `then`/`else` argument of a select.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
#[repr(u8)]
pub enum Choice {
    /// Both arguments matter.
    #[default]
    Both = 0,
    /// The result equals the first argument everywhere in the region.
    Left = 1,
    /// The result equals the second argument everywhere in the region.
    Right = 2,
    /// The result has the sign of the first argument everywhere in the region (and so the same
    /// zero set), but not its value.
    SignLeft = 3,
    /// The result has the sign of the second argument everywhere in the region.
    SignRight = 4,
}

/// How faithful a simplified tape must be.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Fidelity {
    /// The simplified tape has the same values as the full tape in the region.
    #[default]
    Exact,
    /// The simplified tape has the same sign (so the same inside, outside and surface) in the
    /// region, but maybe other values: enough for meshing and inside tests, and the only way to
    /// prune R-function set operations, whose values mix both arguments everywhere.
    Sign,
}

#[derive(Clone, Copy, Debug, PartialEq)]
enum SsaOp {
    Input(u8),
    Const(f64),
    Unary(UnaryOp, u32),
    Binary(BinaryOp, u32, u32),
    Ternary(TernaryOp, u32, u32, u32),
    Sample(u8, u32, u32, u32),
}

impl SsaOp {
    fn args(&self) -> ([u32; 3], usize) {
        match *self {
            SsaOp::Input(_) | SsaOp::Const(_) => ([0; 3], 0),
            SsaOp::Unary(_, a) => ([a, 0, 0], 1),
            SsaOp::Binary(_, a, b) => ([a, b, 0], 2),
            SsaOp::Ternary(_, a, b, c) | SsaOp::Sample(_, a, b, c) => ([a, b, c], 3),
        }
    }

    fn is_leaf(&self) -> bool {
        matches!(self, SsaOp::Input(_) | SsaOp::Const(_))
    }

    /// The same operation over the arguments `f` maps its arguments to.
    #[inline]
    fn with_args(&self, f: impl Fn(u32) -> u32) -> SsaOp {
        match *self {
            SsaOp::Input(_) | SsaOp::Const(_) => *self,
            SsaOp::Unary(o, a) => SsaOp::Unary(o, f(a)),
            SsaOp::Binary(o, a, b) => SsaOp::Binary(o, f(a), f(b)),
            SsaOp::Ternary(o, a, b, c) => SsaOp::Ternary(o, f(a), f(b), f(c)),
            SsaOp::Sample(g, a, b, c) => SsaOp::Sample(g, f(a), f(b), f(c)),
        }
    }

    /// The instruction code of an operation that is not a leaf.
    fn code(&self) -> Code {
        match *self {
            SsaOp::Unary(op, _) => Code::Unary(op),
            SsaOp::Binary(op, _, _) => Code::Binary(op),
            SsaOp::Ternary(op, _, _, _) => Code::Ternary(op),
            SsaOp::Sample(g, _, _, _) => Code::Sample(g),
            SsaOp::Input(_) | SsaOp::Const(_) => unreachable!("leaves were skipped"),
        }
    }
}

/// The operations of `ops` that `outputs` still read, renumbered, and the outputs' new
/// numbers: the backward pass of [`Tape::simplify`].
fn live_only(ops: &[SsaOp], outputs: &[u32]) -> (Vec<SsaOp>, Vec<u32>) {
    let mut live = vec![false; ops.len()];
    for &o in outputs {
        live[o as usize] = true;
    }
    for i in (0..ops.len()).rev() {
        if live[i] {
            let (args, k) = ops[i].args();
            for &a in &args[..k] {
                live[a as usize] = true;
            }
        }
    }
    let mut compact = vec![u32::MAX; ops.len()];
    let mut kept = Vec::with_capacity(ops.len());
    for (i, op) in ops.iter().enumerate() {
        if !live[i] {
            continue;
        }
        let new = op.with_args(|a| compact[a as usize]);
        compact[i] = kept.len() as u32;
        kept.push(new);
    }
    let outputs = outputs.iter().map(|&o| compact[o as usize]).collect();
    (kept, outputs)
}

/// The last operation reading each value of `ssa`; outputs live to the end (`usize::MAX`).
fn last_uses(ssa: &[SsaOp], ssa_outputs: &[u32]) -> Vec<usize> {
    let mut last_use = vec![0usize; ssa.len()];
    for (i, op) in ssa.iter().enumerate() {
        let (args, k) = op.args();
        for &a in &args[..k] {
            last_use[a as usize] = i;
        }
    }
    for &o in ssa_outputs {
        last_use[o as usize] = usize::MAX;
    }
    last_use
}

/// A compiled straight-line program with one or more outputs. A handle: clones share one
/// program, and an absent tape (`Option<Tape>`) costs a pointer, so the many optional parts
/// of an object stay small.
#[derive(Clone, Debug)]
pub struct Tape(Arc<Program>);

const _: () = assert!(size_of::<Option<Tape>>() == size_of::<usize>());

#[derive(Debug)]
struct Program {
    ssa: Box<[SsaOp]>,
    ssa_outputs: Box<[u32]>,
    /// The SSA index each instruction computes.
    instr_ssa: Box<[u32]>,
    instrs: Box<[Instr]>,
    n_regs: u32,
    inputs: [Option<u32>; 4],
    outputs: Box<[Operand]>,
    grids: Arc<[Arc<Grid>]>,
}

impl Tape {
    /// Schedules the parts of `context` that `roots` need into a tape with one output per root.
    pub fn new(context: &Context, roots: &[Node]) -> Tape {
        let nodes = context.reachable(roots);
        let mut index = vec![u32::MAX; context.len()];
        let mut ssa = Vec::with_capacity(nodes.len());
        for (i, node) in nodes.iter().enumerate() {
            index[node.index()] = i as u32;
            let at = |n: Node| index[n.index()];
            ssa.push(match context.op(*node) {
                Op::Input(slot) => SsaOp::Input(slot),
                Op::Const(bits) => SsaOp::Const(f64::from_bits(bits)),
                Op::Unary(op, a) => SsaOp::Unary(op, at(a)),
                Op::Binary(op, a, b) => SsaOp::Binary(op, at(a), at(b)),
                Op::Ternary(op, a, b, c) => SsaOp::Ternary(op, at(a), at(b), at(c)),
                Op::Sample(g, a, b, c) => SsaOp::Sample(g, at(a), at(b), at(c)),
            });
        }
        let outputs: Vec<u32> = roots.iter().map(|r| index[r.index()]).collect();
        Tape::from_ssa(ssa, outputs, context.grids().into())
    }

    fn from_ssa(ssa: Vec<SsaOp>, ssa_outputs: Vec<u32>, grids: Arc<[Arc<Grid>]>) -> Tape {
        let n = ssa.len();
        let last_use = last_uses(&ssa, &ssa_outputs);
        let mut reg_of = vec![u32::MAX; n];
        let mut inputs = [None; 4];
        let mut n_regs = 0u32;
        let mut free: Vec<u32> = Vec::new();
        for (i, op) in ssa.iter().enumerate() {
            if let SsaOp::Input(slot) = op {
                reg_of[i] = n_regs;
                inputs[*slot as usize] = Some(n_regs);
                n_regs += 1;
            }
        }
        let mut instrs = Vec::with_capacity(n);
        let mut instr_ssa = Vec::with_capacity(n);
        for (i, op) in ssa.iter().enumerate() {
            if op.is_leaf() {
                continue;
            }
            let (args, k) = op.args();
            let operand = |a: u32| match ssa[a as usize] {
                SsaOp::Const(c) => Operand::Const(c),
                _ => Operand::Reg(reg_of[a as usize]),
            };
            let mut operands = [Operand::Const(0.0); 3];
            for j in 0..k {
                operands[j] = operand(args[j]);
            }
            let out = free.pop().unwrap_or_else(|| {
                n_regs += 1;
                n_regs - 1
            });
            reg_of[i] = out;
            for j in 0..k {
                let a = args[j] as usize;
                let repeated = args[..j].contains(&args[j]);
                if last_use[a] == i && !repeated && !ssa[a].is_leaf() {
                    free.push(reg_of[a]);
                }
            }
            instrs.push(Instr {
                code: op.code(),
                out,
                args: operands,
            });
            instr_ssa.push(i as u32);
        }
        let outputs: Vec<Operand> = ssa_outputs
            .iter()
            .map(|&o| match ssa[o as usize] {
                SsaOp::Const(c) => Operand::Const(c),
                _ => Operand::Reg(reg_of[o as usize]),
            })
            .collect();
        Tape(Arc::new(Program {
            ssa: ssa.into(),
            ssa_outputs: ssa_outputs.into(),
            instr_ssa: instr_ssa.into(),
            instrs: instrs.into(),
            n_regs,
            inputs,
            outputs: outputs.into(),
            grids,
        }))
    }

    /// The grids the tape's [`Code::Sample`] instructions index.
    pub fn grids(&self) -> &[Arc<Grid>] {
        &self.0.grids
    }

    /// The register instructions, in order.
    pub fn instrs(&self) -> &[Instr] {
        &self.0.instrs
    }

    /// How many registers an evaluator needs.
    pub fn n_regs(&self) -> usize {
        self.0.n_regs as usize
    }

    /// The register that holds each coordinate slot, if the tape reads it.
    pub fn inputs(&self) -> [Option<u32>; 4] {
        self.0.inputs
    }

    /// Where each output is found after evaluation.
    pub fn outputs(&self) -> &[Operand] {
        &self.0.outputs
    }

    /// The bytes the tape's program holds, shared by its clones (the grids it names not
    /// counted).
    pub fn heap_bytes(&self) -> usize {
        let p = &*self.0;
        // The `Arc`'s two counts, then the program and its slices.
        2 * size_of::<usize>()
            + size_of::<Program>()
            + size_of_val(&*p.ssa)
            + size_of_val(&*p.ssa_outputs)
            + size_of_val(&*p.instr_ssa)
            + size_of_val(&*p.instrs)
            + size_of_val(&*p.outputs)
            + size_of_val(&*p.grids)
    }

    /// How many instructions the tape runs.
    pub fn len(&self) -> usize {
        self.0.instrs.len()
    }

    /// Whether the tape runs no instruction (every output is an input or a constant).
    pub fn is_empty(&self) -> bool {
        self.0.instrs.is_empty()
    }

    /// A tape that computes the same outputs over the region where `choices` were recorded
    /// (one per instruction, from [`crate::eval::IntervalEval`]), skipping what cannot matter
    /// there. With [`Fidelity::Sign`] it may also replace operations by an argument of the same
    /// sign, where only the sign of the output is used.
    pub fn simplify(&self, choices: &[Choice], fidelity: Fidelity) -> Tape {
        assert_eq!(
            choices.len(),
            self.0.instrs.len(),
            "one choice per instruction"
        );
        let n = self.0.ssa.len();
        let mut choice_of = vec![Choice::Both; n];
        for (i, &c) in choices.iter().enumerate() {
            choice_of[self.0.instr_ssa[i] as usize] = c;
        }
        let sign_context = match fidelity {
            Fidelity::Exact => Vec::new(),
            Fidelity::Sign => self.sign_context(),
        };
        // Forward: each old value is provided by a new value, either itself (with remapped
        // arguments) or the argument its choice selects.
        let mut map = vec![u32::MAX; n];
        let mut ops: Vec<SsaOp> = Vec::with_capacity(n);
        for (i, op) in self.0.ssa.iter().enumerate() {
            let m = |a: u32| map[a as usize];
            let pick = match (choice_of[i], op) {
                (Choice::Left, SsaOp::Binary(_, a, _)) => Some(*a),
                (Choice::Right, SsaOp::Binary(_, _, b)) => Some(*b),
                (Choice::Left, SsaOp::Ternary(TernaryOp::Select, _, b, _)) => Some(*b),
                (Choice::Right, SsaOp::Ternary(TernaryOp::Select, _, _, c)) => Some(*c),
                (Choice::Left, SsaOp::Ternary(_, a, _, _)) => Some(*a),
                (Choice::Right, SsaOp::Ternary(_, _, b, _)) => Some(*b),
                (Choice::SignLeft, SsaOp::Binary(_, a, _))
                    if sign_context.get(i) == Some(&true) =>
                {
                    Some(*a)
                }
                (Choice::SignRight, SsaOp::Binary(_, _, b))
                    if sign_context.get(i) == Some(&true) =>
                {
                    Some(*b)
                }
                _ => None,
            };
            if let Some(a) = pick {
                map[i] = m(a);
                continue;
            }
            let new = op.with_args(m);
            map[i] = ops.len() as u32;
            ops.push(new);
        }
        let outputs: Vec<u32> = self
            .0
            .ssa_outputs
            .iter()
            .map(|&o| map[o as usize])
            .collect();
        let (kept, outputs) = live_only(&ops, &outputs);
        Tape::from_ssa(kept, outputs, Arc::clone(&self.0.grids))
    }

    /// For each SSA value: whether only its sign can reach the outputs, through operations whose
    /// sign depends only on their arguments' signs (`min`, `max`, R-functions, negation).
    fn sign_context(&self) -> Vec<bool> {
        let n = self.0.ssa.len();
        let mut used = vec![false; n];
        let mut sign_only = vec![true; n];
        for &o in self.0.ssa_outputs.iter() {
            used[o as usize] = true;
        }
        for i in (0..n).rev() {
            let op = self.0.ssa[i];
            let transparent = sign_only[i]
                && matches!(
                    op,
                    SsaOp::Binary(
                        BinaryOp::Min | BinaryOp::Max | BinaryOp::RAnd | BinaryOp::ROr,
                        _,
                        _
                    ) | SsaOp::Unary(UnaryOp::Neg, _)
                );
            let (args, k) = op.args();
            for &a in &args[..k] {
                used[a as usize] = true;
                if !transparent {
                    sign_only[a as usize] = false;
                }
            }
        }
        sign_only.iter().zip(&used).map(|(s, u)| *s && *u).collect()
    }
}
