// Pinocchio -> CasADi bridge: builds a pinocchio::ModelTpl<casadi::SX> from a topology and a
// flat symbolic parameter vector P, and evaluates Pinocchio's algorithms on SX.
//
// Parameter layout of P (must match kinemaforge_opt/symbolic.py, which owns its documentation):
//   per joint (all joints, tree order), 17 entries:
//       R_parent_joint (9, row-major), p_parent_joint (3, m), axis in joint frame (3, normalised
//       here), pitch (1, m/rad), armature (1, kg m^2 or kg)
//   per non-root link (link index 1..L-1), 10 entries: Pinocchio dynamic parameters about the
//       link frame origin, [m, m*c (3), Ixx, Ixy, Iyy, Ixz, Iyz, Izz]
//   gravity (3, m/s^2, world frame)
#pragma once

#include <pinocchio/autodiff/casadi.hpp>
#include <pinocchio/multibody.hpp>

#include <string>
#include <vector>

namespace kfbridge
{
  using SX = casadi::SX;
  using Model = pinocchio::ModelTpl<SX>;
  using Data = pinocchio::DataTpl<SX>;
  using SE3 = pinocchio::SE3Tpl<SX>;

  constexpr int kJointParams = 17;
  constexpr int kLinkParams = 10;

  struct JointSpec
  {
    char type; // 'R' revolute/continuous, 'P' prismatic, 'H' helical, 'F' fixed
    int parent_link;
    int child_link;
  };

  struct Topology
  {
    int n_links = 0;
    std::vector<JointSpec> joints;
    int n_params() const
    {
      return kJointParams * (int)joints.size() + kLinkParams * (n_links - 1) + 3;
    }
  };

  // The symbolic model plus, for every link, the Pinocchio joint it rides on and its
  // placement in that joint's frame (T_joint_link).
  struct SymbolicModel
  {
    Model model;
    std::vector<pinocchio::JointIndex> link_joint;
    std::vector<SE3> T_joint_link;
  };

  Topology parse_topology(const std::string & spec);
  SymbolicModel build_model(const Topology & topo, const SX & P);

  casadi::Function make_aba(const Topology & topo);
  casadi::Function make_rnea(const Topology & topo);
  casadi::Function make_crba(const Topology & topo);
  casadi::Function make_kinetic_energy(const Topology & topo);
  casadi::Function make_potential_energy(const Topology & topo);
  casadi::Function make_link_poses(const Topology & topo);
} // namespace kfbridge
