#include "convert.hpp"

#include <pinocchio/algorithm/aba.hpp>

namespace kfbridge
{
  casadi::Function make_aba(const Topology & topo)
  {
    const int n = count_dofs(topo);
    SX q = SX::sym("q", n), v = SX::sym("v", n), tau = SX::sym("tau", n);
    SX P = SX::sym("P", topo.n_params());
    SymbolicModel sm = build_model(topo, P);
    Data data(sm.model);
    pinocchio::aba(sm.model, data, to_eigen(q), to_eigen(v), to_eigen(tau));
    return casadi::Function(
      "aba", {q, v, tau, P}, {to_sx(data.ddq)}, {"q", "v", "tau", "P"}, {"a"});
  }
} // namespace kfbridge
