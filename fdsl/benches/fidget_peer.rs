//! Builds the same function in the `fidget` crate, our benchmark peer, from a compiled fdsl
//! tape. fidget uses the opposite sign convention (inside is negative), so the root is negated.
//!
//! Shared by the `eval` benchmark and the agreement test (`tests/fidget_agreement.rs`).

use fdsl::compile::{BinaryOp, TernaryOp, UnaryOp};
use fdsl::tape::{Code, Operand, Tape};
use fidget::context::{Context, Node};

/// The fidget context and root node computing `-f` for the first output of `tape`.
pub fn to_fidget(tape: &Tape) -> (Context, Node) {
    let mut ctx = Context::new();
    let mut regs: Vec<Option<Node>> = vec![None; tape.n_regs()];
    let axes = [ctx.x(), ctx.y(), ctx.z()];
    for (slot, reg) in tape.inputs().iter().enumerate() {
        if let Some(r) = reg {
            assert!(slot < 3, "the benchmark models do not depend on time");
            regs[*r as usize] = Some(axes[slot]);
        }
    }
    for instr in tape.instrs() {
        let arg = |ctx: &mut Context, o: Operand| match o {
            Operand::Reg(r) => {
                regs[r as usize].expect("registers are written before they are read")
            }
            Operand::Const(c) => ctx.constant(c as f32),
        };
        let [a, b, c] = instr.args;
        let node = match instr.code {
            Code::Unary(op) => {
                let a = arg(&mut ctx, a);
                unary(&mut ctx, op, a)
            }
            Code::Binary(op) => {
                let (a, b) = (arg(&mut ctx, a), arg(&mut ctx, b));
                binary(&mut ctx, op, a, b)
            }
            Code::Ternary(op) => {
                let (a, b, c) = (arg(&mut ctx, a), arg(&mut ctx, b), arg(&mut ctx, c));
                ternary(&mut ctx, op, a, b, c)
            }
            Code::Sample(_) => panic!("fidget has no sampled grids; the benchmark models use none"),
        };
        regs[instr.out as usize] = Some(node);
    }
    let root = match tape.outputs()[0] {
        Operand::Reg(r) => regs[r as usize].expect("the output is written"),
        Operand::Const(c) => ctx.constant(c as f32),
    };
    let negated = ctx.neg(root).expect("nodes of this context");
    (ctx, negated)
}

fn unary(ctx: &mut Context, op: UnaryOp, a: Node) -> Node {
    match op {
        UnaryOp::Neg => ctx.neg(a),
        UnaryOp::Abs => ctx.abs(a),
        UnaryOp::Sqrt => ctx.sqrt(a),
        UnaryOp::Square => ctx.square(a),
        UnaryOp::Sin => ctx.sin(a),
        UnaryOp::Cos => ctx.cos(a),
        UnaryOp::Tan => ctx.tan(a),
        UnaryOp::Asin => ctx.asin(a),
        UnaryOp::Acos => ctx.acos(a),
        UnaryOp::Atan => ctx.atan(a),
        UnaryOp::Exp => ctx.exp(a),
        UnaryOp::Ln => ctx.ln(a),
        UnaryOp::Floor => ctx.floor(a),
        UnaryOp::Ceil => ctx.ceil(a),
        UnaryOp::Sign => ctx.compare(a, 0.0),
        UnaryOp::Not => ctx.not(a),
    }
    .expect("nodes of this context")
}

fn binary(ctx: &mut Context, op: BinaryOp, a: Node, b: Node) -> Node {
    let r = match op {
        BinaryOp::Add => ctx.add(a, b),
        BinaryOp::Sub => ctx.sub(a, b),
        BinaryOp::Mul => ctx.mul(a, b),
        BinaryOp::Div => ctx.div(a, b),
        BinaryOp::Min => ctx.min(a, b),
        BinaryOp::Max => ctx.max(a, b),
        BinaryOp::Atan2 => ctx.atan2(a, b),
        BinaryOp::Mod => ctx.modulo(a, b),
        BinaryOp::Lt => ctx.less_than(a, b),
        BinaryOp::Le => ctx.less_than_or_equal(a, b),
        BinaryOp::Eq => {
            let c = ctx.compare(a, b).expect("nodes of this context");
            ctx.not(c)
        }
        BinaryOp::And => {
            let (na, nb) = (ctx.not(a).expect("node"), ctx.not(b).expect("node"));
            let either = ctx.or(na, nb).expect("node");
            ctx.not(either)
        }
        BinaryOp::Or => {
            let (na, nb) = (ctx.not(a).expect("node"), ctx.not(b).expect("node"));
            let both = ctx.and(na, nb).expect("node");
            ctx.not(both)
        }
        BinaryOp::Pow => {
            let l = ctx.ln(a).expect("node");
            let m = ctx.mul(b, l).expect("node");
            ctx.exp(m)
        }
        BinaryOp::RAnd | BinaryOp::ROr => {
            let (a2, b2) = (ctx.square(a).expect("node"), ctx.square(b).expect("node"));
            let s = ctx.add(a2, b2).expect("node");
            let root = ctx.sqrt(s).expect("node");
            let sum = ctx.add(a, b).expect("node");
            if op == BinaryOp::RAnd {
                ctx.sub(sum, root)
            } else {
                ctx.add(sum, root)
            }
        }
    };
    r.expect("nodes of this context")
}

fn ternary(ctx: &mut Context, op: TernaryOp, a: Node, b: Node, c: Node) -> Node {
    match op {
        TernaryOp::Select => ctx.if_nonzero_else(a, b, c).expect("node"),
        TernaryOp::BlendMin | TernaryOp::BlendMax => {
            let sign = if op == TernaryOp::BlendMin { 1.0 } else { -1.0 };
            let (a, b) = (
                ctx.mul(a, sign).expect("node"),
                ctx.mul(b, sign).expect("node"),
            );
            let d = ctx.sub(a, b).expect("node");
            let ad = ctx.abs(d).expect("node");
            let gap = ctx.sub(c, ad).expect("node");
            let gap = ctx.max(gap, 0.0).expect("node");
            let h = ctx.div(gap, c).expect("node");
            let h2 = ctx.square(h).expect("node");
            let bump = ctx.mul(h2, c).expect("node");
            let bump = ctx.mul(bump, 0.25).expect("node");
            let m = ctx.min(a, b).expect("node");
            let v = ctx.sub(m, bump).expect("node");
            ctx.mul(v, sign).expect("node")
        }
    }
}
