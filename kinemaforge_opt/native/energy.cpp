#include "convert.hpp"

#include <pinocchio/algorithm/energy.hpp>
#include <pinocchio/algorithm/kinematics.hpp>

namespace kfbridge
{
  casadi::Function make_kinetic_energy(const Topology & topo)
  {
    const int n = count_dofs(topo);
    SX q = SX::sym("q", n), v = SX::sym("v", n);
    SX P = SX::sym("P", topo.n_params());
    SymbolicModel sm = build_model(topo, P);
    Data data(sm.model);
    const SX ke = pinocchio::computeKineticEnergy(sm.model, data, to_eigen(q), to_eigen(v));
    return casadi::Function("kinetic_energy", {q, v, P}, {ke}, {"q", "v", "P"}, {"kinetic_energy"});
  }

  casadi::Function make_potential_energy(const Topology & topo)
  {
    const int n = count_dofs(topo);
    SX q = SX::sym("q", n);
    SX P = SX::sym("P", topo.n_params());
    SymbolicModel sm = build_model(topo, P);
    Data data(sm.model);
    const SX pe = pinocchio::computePotentialEnergy(sm.model, data, to_eigen(q));
    return casadi::Function(
      "potential_energy", {q, P}, {pe}, {"q", "P"}, {"potential_energy"});
  }

  casadi::Function make_link_poses(const Topology & topo)
  {
    const int n = count_dofs(topo);
    SX q = SX::sym("q", n);
    SX P = SX::sym("P", topo.n_params());
    SymbolicModel sm = build_model(topo, P);
    Data data(sm.model);
    pinocchio::forwardKinematics(sm.model, data, to_eigen(q));
    // One vertically stacked (4 L x 4) output: rows 4l..4l+3 are T_world_link for link l.
    SX stacked = SX::zeros(4 * topo.n_links, 4);
    for (int l = 0; l < topo.n_links; ++l)
    {
      const SE3 T_world_link = data.oMi[sm.link_joint[l]] * sm.T_joint_link[l];
      stacked(casadi::Slice(4 * l, 4 * l + 4), casadi::Slice()) = to_sx(T_world_link.toHomogeneousMatrix());
    }
    return casadi::Function("link_poses", {q, P}, {stacked}, {"q", "P"}, {"Ts_world_link"});
  }
} // namespace kfbridge
