#include "convert.hpp"

#include <pinocchio/algorithm/rnea.hpp>

namespace kfbridge
{
  casadi::Function make_rnea(const Topology & topo)
  {
    const int n = count_dofs(topo);
    SX q = SX::sym("q", n), v = SX::sym("v", n), a = SX::sym("a", n);
    SX P = SX::sym("P", topo.n_params());
    SymbolicModel sm = build_model(topo, P);
    Data data(sm.model);
    pinocchio::rnea(sm.model, data, to_eigen(q), to_eigen(v), to_eigen(a));
    return casadi::Function(
      "rnea", {q, v, a, P}, {to_sx(data.tau)}, {"q", "v", "a", "P"}, {"tau"});
  }
} // namespace kfbridge
