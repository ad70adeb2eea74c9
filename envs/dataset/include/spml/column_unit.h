// The unit of a spml/1 column from its name's prefix and its joint's type: the one table of
// units (bench's results.csv and predictions.h5, compare and plot through them, diagnose's notes).
#pragma once

#include <string>
#include <vector>

namespace spml {

// `tau:` N·m, `q:` rad, `qd:` rad/s, `qdd:` rad/s² for a hinge joint; N, m, m/s, m/s² for a
// slide joint (`slide`); `force:` N; `t` s; "" for any other name (Toy's `y`, user features).
std::string column_unit(const std::string& column, bool slide);
// The same, the joint (the text after the prefix) a slide joint when `slide_joints` names it.
// Where no model is known `slide_joints` is empty: every joint counts as a hinge (the
// documented convention).
std::string column_unit(const std::string& column, const std::vector<std::string>& slide_joints = {});

}  // namespace spml
