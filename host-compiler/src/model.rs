//! Plant models: linear affine (continuous and discrete time), exact zero-order-hold discretisation, simulation.
