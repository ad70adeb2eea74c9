// The force plugins of a model as one line of text, for a dataset's provenance (internal header).
#pragma once

#include <sstream>
#include <string>

#include "spml/force_effects.h"

namespace spml {

// "name: type=T joints=a,b key=value ...; " per declared instance.
inline std::string declarations_text(const ForceEffects& fx) {
  std::ostringstream out;
  for (const auto& inst : fx.instances()) {
    out << inst.decl.instance << ": type=" << inst.decl.type << " joints=";
    for (size_t i = 0; i < inst.decl.joints.size(); ++i) out << (i ? "," : "") << inst.decl.joints[i];
    for (const auto& [k, v] : inst.decl.config) out << " " << k << "=" << v;
    out << "; ";
  }
  return out.str();
}

}  // namespace spml
