#include "phos/util/csv.h"

#include <gtest/gtest.h>

#include "phos/util/error.h"
#include "test_util.h"

namespace phos {
namespace {

TEST(ReadCsv, ReadsColumnsSkippingCommentsAndBlankLines) {
  testing::TempDir dir;
  testing::WriteText(dir / "a.csv", "# decay\nt, value\r\n0,1\n\n1,0.5\n");
  CsvTable table = ReadCsv(dir / "a.csv");
  EXPECT_EQ(table.header, (std::vector<std::string>{"t", "value"}));
  EXPECT_EQ(table.row_count(), 2u);
  EXPECT_EQ(table.columns[1][1], 0.5);
  EXPECT_EQ(table.Find("value"), 1);
  EXPECT_EQ(table.Find("nope"), -1);
}

TEST(ReadCsv, BadCellsNameTheLineAndColumn) {
  testing::TempDir dir;
  testing::WriteText(dir / "a.csv", "t,value\n0,1\n1,abc\n");
  try {
    ReadCsv(dir / "a.csv");
    FAIL();
  } catch (const UserError& e) {
    EXPECT_NE(std::string(e.what()).find("a.csv: line 3, column value: expected a finite number, got \"abc\""),
              std::string::npos)
        << e.what();
  }
  testing::WriteText(dir / "b.csv", "t,value\n0\n");
  EXPECT_THROW(ReadCsv(dir / "b.csv"), UserError);
  testing::WriteText(dir / "c.csv", "");
  EXPECT_THROW(ReadCsv(dir / "c.csv"), UserError);
}

}  // namespace
}  // namespace phos
