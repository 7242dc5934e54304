#include "bridge.hpp"

#include <sstream>
#include <stdexcept>

namespace kfbridge
{
  Topology parse_topology(const std::string & spec)
  {
    // "kfbridge/1 <n_links> <n_joints> then per joint: <type> <parent_link> <child_link>"
    std::istringstream in(spec);
    std::string magic;
    int n_joints = 0;
    Topology topo;
    in >> magic >> topo.n_links >> n_joints;
    if (!in || magic != "kfbridge/1")
      throw std::runtime_error("topology spec must start with 'kfbridge/1 <n_links> <n_joints>'");
    if (n_joints != topo.n_links - 1)
      throw std::runtime_error("a tree with n links has n-1 joints");
    std::vector<bool> attached(topo.n_links, false);
    attached[0] = true;
    for (int i = 0; i < n_joints; ++i)
    {
      JointSpec j;
      in >> j.type >> j.parent_link >> j.child_link;
      if (!in)
        throw std::runtime_error("topology spec: joint " + std::to_string(i) + " is truncated");
      if (j.type != 'R' && j.type != 'P' && j.type != 'H' && j.type != 'F')
        throw std::runtime_error("topology spec: joint " + std::to_string(i) + " has unknown type");
      if (j.parent_link < 0 || j.parent_link >= topo.n_links || !attached[j.parent_link])
        throw std::runtime_error(
          "topology spec: joint " + std::to_string(i) + " has a parent not yet in the tree");
      if (j.child_link <= 0 || j.child_link >= topo.n_links || attached[j.child_link])
        throw std::runtime_error(
          "topology spec: joint " + std::to_string(i) + " has an invalid or repeated child");
      attached[j.child_link] = true;
      topo.joints.push_back(j);
    }
    return topo;
  }

  SymbolicModel build_model(const Topology & topo, const SX & P)
  {
    SymbolicModel sm;
    Model & model = sm.model;
    sm.link_joint.assign(topo.n_links, 0);
    sm.T_joint_link.assign(topo.n_links, SE3::Identity());

    const int link_base = kJointParams * (int)topo.joints.size();
    const int gravity_base = link_base + kLinkParams * (topo.n_links - 1);
    model.gravity.linear() << P(gravity_base), P(gravity_base + 1), P(gravity_base + 2);
    model.gravity.angular().setZero();

    for (std::size_t i = 0; i < topo.joints.size(); ++i)
    {
      const JointSpec & js = topo.joints[i];
      const int b = kJointParams * (int)i;
      Eigen::Matrix<SX, 3, 3> R;
      Eigen::Matrix<SX, 3, 1> p, axis;
      for (int r = 0; r < 3; ++r)
        for (int c = 0; c < 3; ++c)
          R(r, c) = P(b + 3 * r + c);
      for (int k = 0; k < 3; ++k)
      {
        p(k) = P(b + 9 + k);
        axis(k) = P(b + 12 + k);
      }
      // The axis parameter is a direction: normalise it so any non-zero vector is valid.
      const SX axis_norm = sqrt(axis(0) * axis(0) + axis(1) * axis(1) + axis(2) * axis(2));
      for (int k = 0; k < 3; ++k)
        axis(k) = axis(k) / axis_norm;
      const SX pitch = P(b + 15);
      const SX armature = P(b + 16);

      // Placement of this joint in the frame of the Pinocchio joint its parent link rides on.
      const SE3 T_parentlink_joint(R, p);
      const SE3 T_pjoint_joint = sm.T_joint_link[js.parent_link] * T_parentlink_joint;
      const pinocchio::JointIndex parent_jid = sm.link_joint[js.parent_link];
      const std::string name = "j" + std::to_string(i);

      if (js.type == 'F')
      {
        sm.link_joint[js.child_link] = parent_jid;
        sm.T_joint_link[js.child_link] = T_pjoint_joint;
        continue;
      }
      pinocchio::JointIndex jid;
      if (js.type == 'R')
        jid = model.addJoint(
          parent_jid, pinocchio::JointModelRevoluteUnalignedTpl<SX>(axis), T_pjoint_joint, name);
      else if (js.type == 'P')
        jid = model.addJoint(
          parent_jid, pinocchio::JointModelPrismaticUnalignedTpl<SX>(axis), T_pjoint_joint, name);
      else
        jid = model.addJoint(
          parent_jid, pinocchio::JointModelHelicalUnalignedTpl<SX>(axis, pitch), T_pjoint_joint,
          name);
      model.armature[model.joints[jid].idx_v()] = armature;
      sm.link_joint[js.child_link] = jid;
      sm.T_joint_link[js.child_link] = SE3::Identity();
    }

    for (int l = 1; l < topo.n_links; ++l)
    {
      const int b = link_base + kLinkParams * (l - 1);
      Eigen::Matrix<SX, 10, 1> pi;
      for (int k = 0; k < 10; ++k)
        pi(k) = P(b + k);
      const pinocchio::InertiaTpl<SX> Y = pinocchio::InertiaTpl<SX>::FromDynamicParameters(pi);
      model.appendBodyToJoint(sm.link_joint[l], Y, sm.T_joint_link[l]);
    }
    return sm;
  }
} // namespace kfbridge
