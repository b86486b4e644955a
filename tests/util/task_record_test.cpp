// Array tasks' shares, indices and done records (util/task_record.h).

#include "phos/util/task_record.h"

#include <gtest/gtest.h>

#include "test_util.h"

namespace phos {
namespace {

TEST(TaskRecord, SharesCoverEveryItemOnceAndDifferByAtMostOne) {
  for (std::size_t items : {0u, 1u, 7u, 12u, 1000u})
    for (int count : {1, 2, 3, 7, 16}) {
      std::size_t next = 0, smallest = SIZE_MAX, largest = 0;
      for (int i = 0; i < count; ++i) {
        const auto [first, last] = TaskShare(items, i, count);
        EXPECT_EQ(first, next) << items << " items, task " << i << "/" << count;
        next = last;
        smallest = std::min(smallest, last - first);
        largest = std::max(largest, last - first);
      }
      EXPECT_EQ(next, items);
      EXPECT_LE(largest - smallest, 1u);
    }
}

TEST(TaskRecord, TaskIndexIsIOverN) {
  int i = -1, n = -1;
  EXPECT_TRUE(ParseTaskIndex("0/1", &i, &n));
  EXPECT_TRUE(ParseTaskIndex("3/4", &i, &n));
  EXPECT_EQ(i, 3);
  EXPECT_EQ(n, 4);
  for (const char* bad : {"4/4", "-1/4", "1/0", "1/", "/4", "1 /4", "a/4", "1/4x", "1", ""})
    EXPECT_FALSE(ParseTaskIndex(bad, &i, &n)) << bad;
}

TEST(TaskRecord, ARecordIsDoneOnlyWholeAndForItsInputs) {
  testing::TempDir dir;
  const auto path = dir / "done" / "task-0-of-2.json";
  EXPECT_FALSE(TaskIsDone(path, "a"));
  WriteTaskDone(path, {"render frames 0:3", "a", {"f0.exr"}, 1.5, "node1"});
  EXPECT_TRUE(TaskIsDone(path, "a"));
  EXPECT_FALSE(TaskIsDone(path, "b"));  // other inputs: another task
  const auto record = ReadTaskDone(path);
  ASSERT_TRUE(record);
  EXPECT_EQ(record->outputs, std::vector<std::string>{"f0.exr"});
  EXPECT_EQ(record->seconds, 1.5);
  // Torn, or a field missing: not done, and why.
  const std::string text = testing::ReadText(path);
  testing::WriteText(path, text.substr(0, text.size() / 2));
  std::string why;
  EXPECT_FALSE(ReadTaskDone(path, &why));
  EXPECT_EQ(why, "does not parse");
  testing::WriteText(path, R"({"format":"phos.task-done/1","task":"t","inputs":"a","outputs":[],"host":"h"})");
  EXPECT_FALSE(ReadTaskDone(path, &why));
  EXPECT_EQ(why, "no seconds");
}

TEST(TaskRecord, OnlyTheTemporariesOfTheGivenOutputsAreRemoved) {
  testing::TempDir dir;
  for (const char* name : {"frame-0001.exr.tmp.77.exr", "frame-0001.exr", "frame-0002.exr.tmp.77.exr", "notes.txt"})
    testing::WriteText(dir / name, "x");
  EXPECT_EQ(RemoveTemporaries(dir.path(), {"frame-0001.exr", "frame-0003.exr"}), 1u);
  EXPECT_FALSE(std::filesystem::exists(dir / "frame-0001.exr.tmp.77.exr"));
  EXPECT_TRUE(std::filesystem::exists(dir / "frame-0001.exr"));          // the finished file stays
  EXPECT_TRUE(std::filesystem::exists(dir / "frame-0002.exr.tmp.77.exr"));  // another task's
}

}  // namespace
}  // namespace phos
