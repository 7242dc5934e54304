// C ABI of the bridge, loaded from Python with ctypes (kinemaforge_opt/symbolic.py).
#include "bridge.hpp"

#include <casadi/config.h>

#include <cstring>
#include <exception>

namespace
{
  char * copy_out(const std::string & s, std::size_t * len)
  {
    char * buf = static_cast<char *>(std::malloc(s.size() + 1));
    std::memcpy(buf, s.data(), s.size());
    buf[s.size()] = '\0';
    if (len)
      *len = s.size();
    return buf;
  }
} // namespace

extern "C" {
// Builds the six functions for a topology and returns them as "<n_bytes>\n<Function::serialize()>"
// records in the order aba, rnea, crba, kinetic_energy, potential_energy, link_poses.
// Returns 0 on success; otherwise 1 and an error message in *out.
int kf_build(const char * spec, char ** out, std::size_t * out_len)
{
  try
  {
    const kfbridge::Topology topo = kfbridge::parse_topology(spec);
    const std::vector<casadi::Function> functions = {
      kfbridge::make_aba(topo),
      kfbridge::make_rnea(topo),
      kfbridge::make_crba(topo),
      kfbridge::make_kinetic_energy(topo),
      kfbridge::make_potential_energy(topo),
      kfbridge::make_link_poses(topo)};
    std::string packed;
    for (const casadi::Function & f : functions)
    {
      const std::string record = f.serialize();
      packed += std::to_string(record.size()) + "\n" + record;
    }
    *out = copy_out(packed, out_len);
    return 0;
  }
  catch (const std::exception & e)
  {
    *out = copy_out(e.what(), out_len);
    return 1;
  }
}

void kf_free(char * p)
{
  std::free(p);
}

const char * kf_versions()
{
  return "casadi " CASADI_VERSION_STRING ", pinocchio " PINOCCHIO_VERSION;
}
}
