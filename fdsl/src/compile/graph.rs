//! The SSA expression graph: an arena of deduplicated operations with constant folding.
//!
//! Building the same operation twice returns the same [`Node`] (common subexpressions are
//! shared), and operations on constants are folded at once, so a graph never holds work that
//! could be done while compiling.

use std::collections::BTreeMap;
use std::sync::Arc;

use super::ops::{BinaryOp, TernaryOp, UnaryOp};
use crate::grid::Grid;
use crate::limits::MAX_GRAPH_NODES;

/// A handle to an operation in a [`Context`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct Node(pub(crate) u32);

impl Node {
    /// The node's index in its context (also its position in topological order).
    pub fn index(self) -> usize {
        self.0 as usize
    }
}

/// One operation of the graph. Arguments always refer to earlier nodes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Op {
    /// Coordinate slot 0..4: `x`/`u`, `y`/`v`, `z`/`w`, `t`.
    Input(u8),
    /// A constant, as the bits of an f64 (so that it can be ordered and deduplicated).
    Const(u64),
    /// A unary operation.
    Unary(UnaryOp, Node),
    /// A binary operation.
    Binary(BinaryOp, Node, Node),
    /// A ternary operation.
    Ternary(TernaryOp, Node, Node, Node),
    /// The grid of this index in [`Context::grids`] sampled at `(x, y, z)`.
    Sample(u8, Node, Node, Node),
}

/// The graph grew past its limit (at most [`MAX_GRAPH_NODES`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
#[error("the expression needs more than {limit} operations")]
pub struct GraphFull {
    /// The graph's limit.
    pub limit: usize,
}

/// An arena of operations with deduplication.
#[derive(Clone, Debug)]
pub struct Context {
    ops: Vec<Op>,
    dedup: BTreeMap<Op, Node>,
    limit: usize,
    grids: Vec<Arc<Grid>>,
}

impl Default for Context {
    fn default() -> Context {
        Context::with_limit(MAX_GRAPH_NODES)
    }
}

impl Context {
    /// An empty graph.
    pub fn new() -> Context {
        Context::default()
    }

    /// An empty graph that may hold `limit` nodes (at most [`MAX_GRAPH_NODES`]).
    pub fn with_limit(limit: usize) -> Context {
        Context {
            ops: Vec::new(),
            dedup: BTreeMap::new(),
            limit: limit.min(MAX_GRAPH_NODES),
            grids: Vec::new(),
        }
    }

    /// How many distinct operations the graph holds.
    pub fn len(&self) -> usize {
        self.ops.len()
    }

    /// Whether the graph holds nothing.
    pub fn is_empty(&self) -> bool {
        self.ops.is_empty()
    }

    /// The operation behind a node.
    pub fn op(&self, node: Node) -> Op {
        self.ops[node.index()]
    }

    /// All operations, in topological order.
    pub fn ops(&self) -> &[Op] {
        &self.ops
    }

    /// The value of a constant node.
    pub fn const_value(&self, node: Node) -> Option<f64> {
        match self.op(node) {
            Op::Const(bits) => Some(f64::from_bits(bits)),
            _ => None,
        }
    }

    fn intern(&mut self, op: Op) -> Result<Node, GraphFull> {
        if let Some(&node) = self.dedup.get(&op) {
            return Ok(node);
        }
        if self.ops.len() >= self.limit {
            return Err(GraphFull { limit: self.limit });
        }
        let node = Node(self.ops.len() as u32);
        self.ops.push(op);
        self.dedup.insert(op, node);
        Ok(node)
    }

    /// The coordinate in slot `slot` (0..4).
    pub fn input(&mut self, slot: u8) -> Result<Node, GraphFull> {
        assert!(slot < 4, "input slot {slot} out of range");
        self.intern(Op::Input(slot))
    }

    /// A constant. All NaNs are the same constant.
    pub fn constant(&mut self, value: f64) -> Result<Node, GraphFull> {
        let value = if value.is_nan() { f64::NAN } else { value };
        // -0.0 and 0.0 differ in bits but not in any operation we fold, except division.
        self.intern(Op::Const(value.to_bits()))
    }

    /// A unary operation, folded or simplified where possible.
    pub fn unary(&mut self, op: UnaryOp, a: Node) -> Result<Node, GraphFull> {
        if let Some(va) = self.const_value(a) {
            return self.constant(op.apply(va));
        }
        match (op, self.op(a)) {
            (UnaryOp::Neg, Op::Unary(UnaryOp::Neg, inner)) => return Ok(inner),
            (UnaryOp::Abs, Op::Unary(UnaryOp::Abs | UnaryOp::Square, _)) => return Ok(a),
            (UnaryOp::Abs, Op::Unary(UnaryOp::Neg, inner)) => {
                return self.unary(UnaryOp::Abs, inner);
            }
            (UnaryOp::Square, Op::Unary(UnaryOp::Neg | UnaryOp::Abs, inner)) => {
                return self.unary(UnaryOp::Square, inner);
            }
            _ => {}
        }
        self.intern(Op::Unary(op, a))
    }

    /// A binary operation, folded or simplified where possible.
    pub fn binary(&mut self, op: BinaryOp, a: Node, b: Node) -> Result<Node, GraphFull> {
        let (ca, cb) = (self.const_value(a), self.const_value(b));
        if let (Some(va), Some(vb)) = (ca, cb) {
            return self.constant(op.apply(va, vb));
        }
        match (op, ca, cb) {
            (BinaryOp::Add, Some(0.0), _) => return Ok(b),
            (BinaryOp::Add | BinaryOp::Sub, _, Some(0.0)) => return Ok(a),
            (BinaryOp::Sub, Some(0.0), _) => return self.unary(UnaryOp::Neg, b),
            (BinaryOp::Mul, Some(1.0), _) => return Ok(b),
            (BinaryOp::Mul | BinaryOp::Div, _, Some(1.0)) => return Ok(a),
            (BinaryOp::Mul, Some(-1.0), _) => return self.unary(UnaryOp::Neg, b),
            (BinaryOp::Mul | BinaryOp::Div, _, Some(-1.0)) => return self.unary(UnaryOp::Neg, a),
            (BinaryOp::Pow, _, Some(e)) => return self.power(a, e),
            _ => {}
        }
        if a == b {
            match op {
                BinaryOp::Min | BinaryOp::Max => return Ok(a),
                BinaryOp::Mul => return self.unary(UnaryOp::Square, a),
                _ => {}
            }
        }
        let (a, b) = if op.is_commutative() && b < a {
            (b, a)
        } else {
            (a, b)
        };
        self.intern(Op::Binary(op, a, b))
    }

    /// `a ^ e` for a constant exponent: small integer powers become multiplications.
    fn power(&mut self, a: Node, e: f64) -> Result<Node, GraphFull> {
        if e == 1.0 {
            return Ok(a);
        }
        if e == 0.5 {
            return self.unary(UnaryOp::Sqrt, a);
        }
        if e.fract() == 0.0 && e.abs() <= 64.0 && e != 0.0 {
            let n = e.abs() as u32;
            let positive = self.integer_power(a, n)?;
            if e > 0.0 {
                return Ok(positive);
            }
            let one = self.constant(1.0)?;
            return self.binary(BinaryOp::Div, one, positive);
        }
        let exponent = self.constant(e)?;
        self.intern(Op::Binary(BinaryOp::Pow, a, exponent))
    }

    /// `a^n` by repeated squaring, `n >= 1`.
    fn integer_power(&mut self, a: Node, n: u32) -> Result<Node, GraphFull> {
        if n == 1 {
            return Ok(a);
        }
        let half = self.integer_power(a, n / 2)?;
        let square = self.unary(UnaryOp::Square, half)?;
        if n % 2 == 1 {
            self.binary(BinaryOp::Mul, square, a)
        } else {
            Ok(square)
        }
    }

    /// A ternary operation, folded or simplified where possible.
    pub fn ternary(&mut self, op: TernaryOp, a: Node, b: Node, c: Node) -> Result<Node, GraphFull> {
        let (ca, cb, cc) = (
            self.const_value(a),
            self.const_value(b),
            self.const_value(c),
        );
        if let (Some(va), Some(vb), Some(vc)) = (ca, cb, cc) {
            return self.constant(op.apply(va, vb, vc));
        }
        if op == TernaryOp::Select {
            if let Some(cond) = ca {
                return Ok(if cond != 0.0 { b } else { c });
            }
            if b == c {
                return Ok(b);
            }
        }
        self.intern(Op::Ternary(op, a, b, c))
    }

    /// The grid `grid` sampled at `(x, y, z)` (folded when all three are constants). A
    /// context holds at most [`crate::grid::MAX_GRIDS`] distinct grids; the lowering checks
    /// the options' grids against that limit before it calls this.
    pub fn sample(
        &mut self,
        grid: &Arc<Grid>,
        x: Node,
        y: Node,
        z: Node,
    ) -> Result<Node, GraphFull> {
        if let (Some(vx), Some(vy), Some(vz)) = (
            self.const_value(x),
            self.const_value(y),
            self.const_value(z),
        ) {
            return self.constant(grid.value([vx, vy, vz]));
        }
        let index = match self
            .grids
            .iter()
            .position(|g| Arc::ptr_eq(g, grid) || g == grid)
        {
            Some(i) => i,
            None => {
                self.grids.push(Arc::clone(grid));
                self.grids.len() - 1
            }
        };
        let index = u8::try_from(index).expect("the options hold at most MAX_GRIDS grids");
        self.intern(Op::Sample(index, x, y, z))
    }

    /// The grids [`Op::Sample`] indexes.
    pub fn grids(&self) -> &[Arc<Grid>] {
        &self.grids
    }

    /// The nodes each root depends on (the roots included), in topological order.
    pub fn reachable(&self, roots: &[Node]) -> Vec<Node> {
        let mut live = vec![false; self.ops.len()];
        for root in roots {
            live[root.index()] = true;
        }
        for i in (0..self.ops.len()).rev() {
            if !live[i] {
                continue;
            }
            match self.ops[i] {
                Op::Input(_) | Op::Const(_) => {}
                Op::Unary(_, a) => live[a.index()] = true,
                Op::Binary(_, a, b) => {
                    live[a.index()] = true;
                    live[b.index()] = true;
                }
                Op::Ternary(_, a, b, c) | Op::Sample(_, a, b, c) => {
                    live[a.index()] = true;
                    live[b.index()] = true;
                    live[c.index()] = true;
                }
            }
        }
        (0..self.ops.len())
            .filter(|&i| live[i])
            .map(|i| Node(i as u32))
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn folding_and_sharing() {
        let mut ctx = Context::new();
        let x = ctx.input(0).unwrap();
        let two = ctx.constant(2.0).unwrap();
        let three = ctx.constant(3.0).unwrap();
        let six = ctx.binary(BinaryOp::Mul, two, three).unwrap();
        assert_eq!(ctx.const_value(six), Some(6.0));
        let a = ctx.binary(BinaryOp::Add, x, six).unwrap();
        let b = ctx.binary(BinaryOp::Add, six, x).unwrap();
        assert_eq!(a, b, "commutative operations are shared");
        let sq = ctx.binary(BinaryOp::Pow, x, two).unwrap();
        assert_eq!(ctx.op(sq), Op::Unary(UnaryOp::Square, x));
        let same = ctx.binary(BinaryOp::Mul, x, x).unwrap();
        assert_eq!(sq, same);
        let neg = ctx.unary(UnaryOp::Neg, x).unwrap();
        assert_eq!(ctx.unary(UnaryOp::Neg, neg).unwrap(), x);
    }

    #[test]
    fn integer_powers_become_multiplications() {
        let mut ctx = Context::new();
        let x = ctx.input(0).unwrap();
        let five = ctx.constant(5.0).unwrap();
        let p = ctx.binary(BinaryOp::Pow, x, five).unwrap();
        let Op::Binary(BinaryOp::Mul, _, _) = ctx.op(p) else {
            panic!("{:?}", ctx.op(p))
        };
        let m2 = ctx.constant(-2.0).unwrap();
        let p = ctx.binary(BinaryOp::Pow, x, m2).unwrap();
        let Op::Binary(BinaryOp::Div, _, _) = ctx.op(p) else {
            panic!("{:?}", ctx.op(p))
        };
        let half = ctx.constant(0.25).unwrap();
        let p = ctx.binary(BinaryOp::Pow, x, half).unwrap();
        assert_eq!(ctx.op(p), Op::Binary(BinaryOp::Pow, x, half));
    }

    #[test]
    fn select_on_constants_picks_a_branch() {
        let mut ctx = Context::new();
        let x = ctx.input(0).unwrap();
        let y = ctx.input(1).unwrap();
        let one = ctx.constant(1.0).unwrap();
        assert_eq!(ctx.ternary(TernaryOp::Select, one, x, y).unwrap(), x);
        assert_eq!(ctx.ternary(TernaryOp::Select, y, x, x).unwrap(), x);
    }

    #[test]
    fn the_node_limit_is_an_error() {
        let mut ctx = Context::new();
        let mut acc = ctx.input(0).unwrap();
        let mut result = Ok(acc);
        for i in 0..MAX_GRAPH_NODES + 10 {
            let c = match ctx.constant(i as f64 + 0.5) {
                Ok(c) => c,
                Err(e) => {
                    result = Err(e);
                    break;
                }
            };
            result = ctx.binary(BinaryOp::Add, acc, c);
            match result {
                Ok(n) => acc = n,
                Err(_) => break,
            }
        }
        assert_eq!(
            result,
            Err(GraphFull {
                limit: MAX_GRAPH_NODES
            })
        );
        assert_eq!(ctx.len(), MAX_GRAPH_NODES);
    }
}
