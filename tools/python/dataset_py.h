// Dataset <-> the module's dict ({"splits": {name: {X, Y, t, x_columns, y_columns}},
// "model": {...} or None, "provenance": {...}}), for the parts that take a dataset either
// as a file or as such a dict.
#pragma once

#include "convert.h"

namespace spml::py {

pb::dict dataset_dict(const Dataset& ds);
Dataset dataset_from(const pb::handle& splits, const pb::handle& model, const pb::handle& provenance);
// A dataset given as a path (read and validated) or as a read_dataset()-style dict.
Dataset dataset_arg(const pb::handle& data);

}  // namespace spml::py
