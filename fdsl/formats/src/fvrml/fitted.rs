//! Domains fitted to implicit solids a file writes without `bboxSize`, by the rule the command
//! line's `new:` follows ([`model::object::fit_domain`]), so that the same bounded formula
//! gets the same domain from a file, from a command and, carried in the object's op, from a
//! peer. A solid that is really unbounded (or empty) keeps no domain, and the loader says why
//! in the words `new:` uses. `bboxSize -1 -1 -1` says "no domain" on purpose (what `save`
//! writes for a solid without one, so that loading gives it back as it was): it is not fitted.
//!
//! Fitting costs up to `MAX_FIT_CELLS` interval evaluations of the formula's tape a solid, so
//! one load spends at most [`MAX_LOAD_FIT_WORK`] cell-instructions over all of them; past it,
//! solids keep no domain and a warning says to give them one.

use super::MAX_LOAD_FIT_WORK;
use super::document::{Node, Value};
use super::read::Scope;
use model::object::fit::MAX_FIT_CELLS;
use model::object::{
    Field, FitError, Geometry, Object, ObjectError, Shape, Slot, fit_domain_within,
};

/// Why a solid of the file got no domain, for a warning at its definition.
#[derive(Debug)]
pub(super) enum NotFitted {
    /// The fit itself refused it (unbounded, empty, too intricate).
    Fit(FitError),
    /// The load's budget ran out before this solid.
    Budget,
    /// The fitted domain could not be set (the object model refused it).
    Refused(ObjectError),
}

impl std::fmt::Display for NotFitted {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            NotFitted::Fit(e) => write!(f, "no domain fits: {e}"),
            NotFitted::Budget => write!(
                f,
                "no domain was fitted: this load spent its {MAX_LOAD_FIT_WORK} cell-instructions \
                 of fitting on earlier solids; give it a `bboxSize`"
            ),
            NotFitted::Refused(e) => write!(f, "the fitted domain was refused: {e}"),
        }
    }
}

/// Fits a domain to the implicit geometry and implicit container of `object`, read from the
/// shape `node`, where the file gives them no `bboxSize`, spending from `work_left`; returns,
/// per slot, why one got none. A shapeless `FShape` (geometry `"0"`, physics for its group:
/// [`super::lend`]) is left as it is.
pub(super) fn fit_domains(
    object: &mut Object,
    scope: &Scope<'_>,
    node: &Node,
    work_left: &mut u64,
) -> Vec<(Slot, NotFitted)> {
    let mut not_fitted = Vec::new();
    if super::lend::written_as_carrier(scope, node) {
        return not_fitted;
    }
    for (slot, path) in [
        (Slot::Geometry, &["geometry"][..]),
        (Slot::Container, &["physics", "container"][..]),
    ] {
        if !without_bbox(scope, node, path) {
            continue;
        }
        let data = object.data();
        let geometry = match slot {
            Slot::Geometry => data.geometry.as_ref(),
            _ => data.physics.container.as_ref(),
        };
        let Some(geometry) = geometry.filter(|g| needs_domain(g)) else {
            continue;
        };
        let Some(tape) = object.tape(slot) else {
            continue;
        };
        let per_cell = tape.len().max(1) as u64;
        let max_cells = usize::try_from(*work_left / per_cell)
            .unwrap_or(usize::MAX)
            .min(MAX_FIT_CELLS);
        let (fitted, n_cells) = fit_domain_within(tape, 0.0, max_cells);
        *work_left = work_left.saturating_sub(n_cells as u64 * per_cell);
        let domain = match fitted {
            Ok(domain) => domain,
            Err(FitError::TooComplex) if max_cells < MAX_FIT_CELLS => {
                not_fitted.push((slot, NotFitted::Budget));
                continue;
            }
            Err(e) => {
                not_fitted.push((slot, NotFitted::Fit(e)));
                continue;
            }
        };
        let geometry = Box::new(Geometry {
            domain: Some(domain),
            ..geometry.clone()
        });
        let field = match slot {
            Slot::Geometry => Field::Geometry(Some(geometry)),
            _ => Field::Container(Some(geometry)),
        };
        if let Err(e) = object.set(field) {
            not_fitted.push((slot, NotFitted::Refused(e)));
        }
    }
    not_fitted
}

/// Whether the node at `path` below `node` (each step the last field of that name, through
/// `USE`) is an `FGeometry` written without `bboxSize`.
fn without_bbox(scope: &Scope<'_>, node: &Node, path: &[&str]) -> bool {
    let mut at = node;
    for name in path {
        let Some(field) = at.fields.iter().rev().find(|f| f.name == *name) else {
            return false;
        };
        let Value::Node(r) = &field.value else {
            return false;
        };
        let Ok(Some(next)) = scope.resolve(r) else {
            return false;
        };
        at = next;
    }
    at.type_name == "FGeometry" && !at.fields.iter().any(|f| f.name == "bboxSize")
}

/// An implicit shape written without a domain.
fn needs_domain(geometry: &Geometry) -> bool {
    geometry.domain.is_none() && matches!(geometry.shape, Shape::Implicit(_))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fvrml::document::NodeRef;
    use crate::fvrml::parse;
    use model::object::{Formula, ObjectData, fit_domain};

    #[test]
    fn fitting_spends_the_loads_budget_and_stops_when_it_is_spent() {
        let text = "FShape { geometry FGeometry { definition \"1-x^2-y^2-z^2\" } }";
        let parsed = parse(text);
        let scope = Scope::new(&parsed.document, 0, None);
        let NodeRef::Node(node) = &parsed.document.nodes[0] else {
            panic!("a node");
        };
        let ball = || {
            Object::new(ObjectData {
                geometry: Some(Geometry::implicit(Formula::new("1-x^2-y^2-z^2").unwrap())),
                ..ObjectData::default()
            })
            .unwrap()
        };
        let mut object = ball();
        let mut left = MAX_LOAD_FIT_WORK;
        assert!(fit_domains(&mut object, &scope, node, &mut left).is_empty());
        let tape = object.tape(Slot::Geometry).unwrap().clone();
        let domain = object.data().geometry.as_ref().unwrap().domain;
        assert_eq!(domain, Some(fit_domain(&tape, 0.0).unwrap()));
        let spent = MAX_LOAD_FIT_WORK - left;
        let (_, n_cells) = fit_domain_within(&tape, 0.0, MAX_FIT_CELLS);
        assert_eq!(spent, n_cells as u64 * tape.len() as u64);
        // With less left than this solid takes, it keeps no domain and the budget is spent.
        let mut short = spent / 2;
        let mut object = ball();
        let why = fit_domains(&mut object, &scope, node, &mut short);
        assert!(
            matches!(why.as_slice(), [(Slot::Geometry, NotFitted::Budget)]),
            "{why:?}"
        );
        assert!(why[0].1.to_string().contains("give it a `bboxSize`"));
        assert_eq!(object.data().geometry.as_ref().unwrap().domain, None);
        assert!(short < tape.len() as u64, "{short}");
    }
}
