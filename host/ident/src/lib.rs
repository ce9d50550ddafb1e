//! ocm-ident (being written).
