//! Accuracy evaluation of estimated trajectories.

pub mod relations;

pub use relations::{
    ErrorStats, EvalError, LOCAL_SPAN, RELATION_TIME_TOLERANCE, Relation, RelationErrors, evaluate,
    evaluate_relations, read_relations,
};
