//! ocm-fem (being written).
