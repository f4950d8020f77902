//! [`SliceEval`]: a tape evaluated in f64 over many points at once, for the box-restricted
//! sampler. It runs one instruction at a time over a chunk of [`LANES`] points, so dispatch
//! costs once per instruction and chunk, and each lane applies the very operation the point
//! evaluator applies (`UnaryOp::apply`, `BinaryOp::apply`, `TernaryOp::apply`, in f64 with no
//! contraction into fused operations): every value is bit for bit
//! [`PointEval`](fdsl::eval::PointEval)'s at the same point. (the language's own bulk evaluator,
//! `BulkEval`, runs in f32 and cannot give the sampler's values.)

use fdsl::compile::{BinaryOp, UnaryOp};
use fdsl::tape::{Code, Operand, Tape};

/// Points evaluated together per instruction.
pub(crate) const LANES: usize = 64;

type Lanes = [f64; LANES];

/// Evaluates a tape's first output over slices of points in f64.
#[derive(Clone, Debug)]
pub(crate) struct SliceEval {
    tape: Tape,
    regs: Vec<Lanes>,
    /// The arguments of the instruction being run, copied out of the registers (an argument
    /// may share its register with the output).
    args: Box<[Lanes; 3]>,
}

/// `o[i] = body` for every lane.
macro_rules! lanes {
    ($o:ident, |$i:ident| $body:expr) => {
        for $i in 0..LANES {
            $o[$i] = $body;
        }
    };
}

impl SliceEval {
    /// An evaluator for `tape` (allocates its registers once).
    pub(crate) fn new(tape: &Tape) -> SliceEval {
        SliceEval {
            tape: tape.clone(),
            regs: vec![[0.0; LANES]; tape.n_regs()],
            args: Box::new([[0.0; LANES]; 3]),
        }
    }

    /// The first output at the points `(xs[i], ys[i], zs[i], t)`, written to `out[i]`.
    pub(crate) fn eval(&mut self, xs: &[f64], ys: &[f64], zs: &[f64], t: f64, out: &mut [f64]) {
        let n = out.len();
        assert!(
            xs.len() == n && ys.len() == n && zs.len() == n,
            "coordinate and output slices differ in length"
        );
        let inputs = self.tape.inputs();
        let mut start = 0;
        while start < n {
            let len = LANES.min(n - start);
            let coords = [
                &xs[start..start + len],
                &ys[start..start + len],
                &zs[start..start + len],
            ];
            for (slot, reg) in inputs.iter().enumerate() {
                let Some(r) = reg else { continue };
                let lanes = &mut self.regs[*r as usize];
                if slot == 3 {
                    lanes.fill(t);
                } else {
                    lanes[..len].copy_from_slice(coords[slot]);
                }
            }
            self.run();
            let chunk = &mut out[start..start + len];
            match self.tape.outputs()[0] {
                Operand::Reg(r) => chunk.copy_from_slice(&self.regs[r as usize][..len]),
                Operand::Const(c) => chunk.fill(c),
            }
            start += len;
        }
    }

    fn run(&mut self) {
        let regs = &mut self.regs;
        let args = &mut *self.args;
        let grids = self.tape.grids();
        for instr in self.tape.instrs().iter() {
            for (k, arg) in instr.args.iter().take(instr.code.n_args()).enumerate() {
                match *arg {
                    Operand::Reg(r) => args[k] = regs[r as usize],
                    Operand::Const(c) => args[k].fill(c),
                }
            }
            let o = &mut regs[instr.out as usize];
            let [a, b, c] = &*args;
            match instr.code {
                Code::Unary(op) => unary(op, o, a),
                Code::Binary(op) => binary(op, o, a, b),
                Code::Ternary(op) => lanes!(o, |i| op.apply(a[i], b[i], c[i])),
                Code::Sample(g) => lanes!(o, |i| grids[g as usize].value([a[i], b[i], c[i]])),
            }
        }
    }
}

/// A unary operation over the lanes; the common ones get a loop of their own.
#[inline(always)]
fn unary(op: UnaryOp, o: &mut Lanes, a: &Lanes) {
    match op {
        UnaryOp::Neg => lanes!(o, |i| UnaryOp::Neg.apply(a[i])),
        UnaryOp::Abs => lanes!(o, |i| UnaryOp::Abs.apply(a[i])),
        UnaryOp::Sqrt => lanes!(o, |i| UnaryOp::Sqrt.apply(a[i])),
        UnaryOp::Square => lanes!(o, |i| UnaryOp::Square.apply(a[i])),
        _ => lanes!(o, |i| op.apply(a[i])),
    }
}

/// A binary operation over the lanes; the common ones get a loop of their own.
#[inline(always)]
fn binary(op: BinaryOp, o: &mut Lanes, a: &Lanes, b: &Lanes) {
    match op {
        BinaryOp::Add => lanes!(o, |i| BinaryOp::Add.apply(a[i], b[i])),
        BinaryOp::Sub => lanes!(o, |i| BinaryOp::Sub.apply(a[i], b[i])),
        BinaryOp::Mul => lanes!(o, |i| BinaryOp::Mul.apply(a[i], b[i])),
        BinaryOp::Div => lanes!(o, |i| BinaryOp::Div.apply(a[i], b[i])),
        BinaryOp::Min => lanes!(o, |i| BinaryOp::Min.apply(a[i], b[i])),
        BinaryOp::Max => lanes!(o, |i| BinaryOp::Max.apply(a[i], b[i])),
        _ => lanes!(o, |i| op.apply(a[i], b[i])),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use fdsl::Function;
    use fdsl::eval::PointEval;

    #[test]
    fn slices_equal_the_point_evaluator_bit_for_bit() {
        let sources = [
            "1 - sqrt(x^2 + y^2 + z^2)",
            "min(max(x, y) - 0.3, sin(3*z) + t) / (1 + abs(x*y))",
            "blend_and(0.5 - x^2 - y^2, 0.4 - z, 0.2) + atan2(y, x) * exp(-z) - ln(1 + x^2)",
            "0.25",
        ];
        for source in sources {
            let tape = Function::parse(source).unwrap().tape();
            let mut slices = SliceEval::new(&tape);
            let mut point = PointEval::new(&tape);
            // 150 points: two full chunks and a partial one.
            let n = 2 * LANES + 22;
            let at = |i: usize, k: f64| ((i as f64 + 1.0) * k).sin() * 1.3;
            let xs: Vec<f64> = (0..n).map(|i| at(i, 0.37)).collect();
            let ys: Vec<f64> = (0..n).map(|i| at(i, 0.73)).collect();
            let zs: Vec<f64> = (0..n).map(|i| at(i, 1.11)).collect();
            let mut out = vec![0.0; n];
            slices.eval(&xs, &ys, &zs, 0.5, &mut out);
            for i in 0..n {
                let want = point.eval([xs[i], ys[i], zs[i], 0.5]);
                assert_eq!(out[i].to_bits(), want.to_bits(), "{source} at point {i}");
            }
        }
    }
}
