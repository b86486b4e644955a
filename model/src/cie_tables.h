#pragma once
// The CIE tables photometry.cpp uses (sources in cie_tables.cpp): values on
// a uniform wavelength grid from first_nm in steps of step_nm.

#include <cstddef>

namespace phos::cie {

struct UniformTable {
  double first_nm;
  double step_nm;
  const double* values;
  std::size_t count;
};

extern const UniformTable kPhotopicVTable;  // V(lambda), 360-830 nm at 1 nm
extern const UniformTable kScotopicVTable;  // V'(lambda), 380-780 nm at 1 nm
extern const UniformTable kD65Table;        // D65, 300-830 nm at 5 nm
extern const UniformTable kF11Table;        // F11, 380-780 nm at 5 nm

}  // namespace phos::cie
