"""The nonlinear terms: polynomials, networks, branch bases and the CPD decoupling."""
