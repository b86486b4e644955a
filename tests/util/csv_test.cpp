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

// A spreadsheet's export quotes a header that holds the separator.
TEST(ReadCsv, AQuotedFieldMayHoldTheSeparator) {
  CsvTable table = ParseCsv("\"time, s\",\"value, \"\"counts\"\"\" , plain\n0,1,2\n1,\"0.5\",3\n", "q.csv");
  EXPECT_EQ(table.header, (std::vector<std::string>{"time, s", "value, \"counts\"", "plain"}));
  ASSERT_EQ(table.row_count(), 2u);
  EXPECT_EQ(table.columns[1][1], 0.5);
  table = ParseCsv("\"t\";\"L; cd/m2\"\n0;1\n", "semicolon.csv");
  EXPECT_EQ(table.header, (std::vector<std::string>{"t", "L; cd/m2"}));
  // An unclosed quote is plain text, as it was.
  table = ParseCsv("\"t,value\n0,1\n", "open.csv");
  EXPECT_EQ(table.header, (std::vector<std::string>{"\"t", "value"}));
}

// A header column without a name (a trailing separator) is one line naming it,
// not "column : expected a finite number" at the first row.
TEST(ReadCsv, EveryHeaderColumnHasAName) {
  try {
    ParseCsv("t,value,\n0,1,\n", "trailing.csv");
    FAIL();
  } catch (const UserError& e) {
    EXPECT_EQ(std::string(e.what()),
              "trailing.csv: line 1: header: column 3 of 3 has no name (a separator at the end of the line?)");
  }
  EXPECT_THROW(ParseCsv("t,,value\n0,1,2\n", "middle.csv"), UserError);
}

TEST(ReadCsv, DetectsTheSeparator) {
  testing::TempDir dir;
  struct Case {
    std::string name, text;
    char separator;
  } cases[] = {
      {"comma.csv", "t (s),red,green\n0,1.5,2\n0.5,1,-3e-2\n", ','},
      {"semicolon.csv", "t (s);red;green\r\n0;1.5;2\r\n0.5;1;-3e-2\r\n", ';'},
      {"tab.txt", "t (s)\tred\tgreen\n0\t1.5\t2\n0.5 \t 1\t-3e-2\n", '\t'},
      {"spaces.dat", "# aligned\n  t_s    red   green\n  0      1.5   2\n  0.5\t  1    -3e-2\n", ' '},
  };
  for (const Case& c : cases) {
    testing::WriteText(dir / c.name, c.text);
    const CsvTable table = ReadCsv(dir / c.name);
    EXPECT_EQ(table.separator, c.separator) << c.name;
    EXPECT_TRUE(table.has_header) << c.name;
    ASSERT_EQ(table.header.size(), 3u) << c.name;
    EXPECT_EQ(table.header[1], "red") << c.name;
    EXPECT_EQ(table.columns[0], (std::vector<double>{0, 0.5})) << c.name;
    EXPECT_EQ(table.columns[2], (std::vector<double>{2, -0.03})) << c.name;
  }
  EXPECT_EQ(ReadCsv(dir / "comma.csv").header[0], "t (s)");
  EXPECT_EQ(ReadCsv(dir / "spaces.dat").header[0], "t_s");
}

TEST(ReadCsv, AFirstLineOfNumbersIsData) {
  testing::TempDir dir;
  testing::WriteText(dir / "a.csv", "0;1\n1;0.5\n");
  const CsvTable table = ReadCsv(dir / "a.csv");
  EXPECT_FALSE(table.has_header);
  EXPECT_EQ(table.header, (std::vector<std::string>{"column 1", "column 2"}));
  EXPECT_EQ(table.row_count(), 2u);
  EXPECT_EQ(table.columns[1][0], 1);
}

TEST(ReadCsv, ADecimalCommaIsNamed) {
  testing::TempDir dir;
  testing::WriteText(dir / "a.csv", "t;value\n0;1\n0,5;2\n");
  EXPECT_NE(testing::ErrorOfType<UserError>([&] {
              ReadCsv(dir / "a.csv");
            }).find("a.csv: line 3, column t: expected a finite number, got \"0,5\" (decimal commas"),
            std::string::npos);
  // A line of another width names its line.
  testing::WriteText(dir / "b.txt", "t value\n0 1\n1 2 3\n");
  EXPECT_NE(
      testing::ErrorOfType<UserError>([&] { ReadCsv(dir / "b.txt"); }).find("b.txt: line 3: expected 2 columns, got 3"),
      std::string::npos);
}

// Limits before allocation (docs/design.md, "Errors"): columns and rows are counted
// as they are read, and only regular files are read.
TEST(ReadCsv, ColumnsRowsAndFileKindsHaveLimits) {
  testing::TempDir dir;
  std::string wide = "t";
  for (std::size_t c = 0; c < kMaxCsvColumns; ++c) wide += ",v";
  testing::WriteText(dir / "wide.csv", wide + "\n");
  EXPECT_EQ(testing::ErrorOfType<UserError>([&] { ReadCsv(dir / "wide.csv"); }),
            (dir / "wide.csv").string() + ": line 1: more than the limit of 4096 columns");
  EXPECT_EQ(ParseCsv("t,v\n0,1\n1,2\n", "mem.csv").row_count(), 2u);
  EXPECT_NE(testing::ErrorOfType<UserError>([&] { ReadCsv("/dev/zero"); }).find("/dev/zero: not a regular file"),
            std::string::npos);
}

}  // namespace
}  // namespace phos
