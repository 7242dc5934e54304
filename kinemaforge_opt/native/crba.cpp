#include "convert.hpp"

#include <pinocchio/algorithm/crba.hpp>

namespace kfbridge
{
  casadi::Function make_crba(const Topology & topo)
  {
    const int n = count_dofs(topo);
    SX q = SX::sym("q", n);
    SX P = SX::sym("P", topo.n_params());
    SymbolicModel sm = build_model(topo, P);
    Data data(sm.model);
    pinocchio::crba(sm.model, data, to_eigen(q));
    // CRBA fills the upper triangle only; mirror it into a full symmetric matrix.
    data.M.template triangularView<Eigen::StrictlyLower>() =
      data.M.transpose().template triangularView<Eigen::StrictlyLower>();
    return casadi::Function("crba", {q, P}, {to_sx(data.M)}, {"q", "P"}, {"M"});
  }
} // namespace kfbridge
