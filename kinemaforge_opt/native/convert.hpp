// Conversions between casadi::SX column vectors/matrices and Eigen matrices of SX scalars.
#pragma once

#include "bridge.hpp"

namespace kfbridge
{
  inline Eigen::Matrix<SX, Eigen::Dynamic, 1> to_eigen(const SX & x)
  {
    Eigen::Matrix<SX, Eigen::Dynamic, 1> out(x.size1());
    for (casadi_int i = 0; i < x.size1(); ++i)
      out(i) = x(i);
    return out;
  }

  template<typename Derived>
  SX to_sx(const Eigen::MatrixBase<Derived> & m)
  {
    SX out = SX::zeros(m.rows(), m.cols());
    for (Eigen::Index r = 0; r < m.rows(); ++r)
      for (Eigen::Index c = 0; c < m.cols(); ++c)
        out(r, c) = m(r, c);
    return out;
  }

  inline int count_dofs(const Topology & topo)
  {
    int n = 0;
    for (const JointSpec & j : topo.joints)
      n += (j.type == 'F') ? 0 : 1;
    return n;
  }
} // namespace kfbridge
