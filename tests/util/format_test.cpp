#include "phos/util/format.h"

#include <cmath>
#include <gtest/gtest.h>
#include <random>

namespace phos {
namespace {

TEST(FormatDouble, ShortestFormReadsBackExactly) {
  EXPECT_EQ(FormatDouble(0.1), "0.1");
  EXPECT_EQ(FormatDouble(0.0), "0");
  EXPECT_EQ(FormatDouble(1e-300), "1e-300");
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<double> exponent(-300, 300);
  for (int i = 0; i < 10000; ++i) {
    double v = std::pow(10.0, exponent(rng)) * (rng() % 2 ? 1 : -1);
    double back = 0;
    ASSERT_TRUE(ParseDouble(FormatDouble(v), &back)) << FormatDouble(v);
    EXPECT_EQ(back, v);
  }
}

TEST(FormatShort, RoundsForPeople) {
  EXPECT_EQ(FormatShort(1.5056999999999998), "1.506");
  EXPECT_EQ(FormatShort(2.0), "2");
  EXPECT_EQ(RoundDownSignificant(0.4649000464900047), 0.46);
  EXPECT_EQ(RoundDownSignificant(0.0099), 0.0099);
  EXPECT_EQ(RoundDownSignificant(123456), 120000);
  for (double v : {0.3, 0.7, 1.0, 2.5e-7, 9.99e5}) EXPECT_LE(RoundDownSignificant(v), v) << v;
}

TEST(ParseDouble, RejectsWhatIsNotOneFiniteNumber) {
  double v = 0;
  EXPECT_TRUE(ParseDouble("+2.5", &v));
  EXPECT_EQ(v, 2.5);
  for (const char* bad : {"", "abc", "1.0x", "nan", "inf", "1e999", " 1", "1,2"})
    EXPECT_FALSE(ParseDouble(bad, &v)) << bad;
}

TEST(ParseDoubleList, SplitsOnCommasAndNamesTheBadItem) {
  std::vector<double> values;
  std::string bad;
  ASSERT_TRUE(ParseDoubleList("1,0.5,0", &values, &bad));
  EXPECT_EQ(values, (std::vector<double>{1, 0.5, 0}));
  EXPECT_FALSE(ParseDoubleList("1,,2", &values, &bad));
  EXPECT_EQ(bad, "");
  EXPECT_FALSE(ParseDoubleList("1,x", &values, &bad));
  EXPECT_EQ(bad, "x");
}

TEST(JoinComma, JoinsItemsAsTextWithCommas) {
  EXPECT_EQ(JoinComma(std::vector<std::string>{}), "");
  EXPECT_EQ(JoinComma(std::vector<std::string>{"uv"}), "uv");
  EXPECT_EQ(JoinComma(std::vector<std::string>{"uv", "blue", "white"}), "uv, blue, white");
  // Through a projection, as the messages list numbers and fields of records.
  EXPECT_EQ(JoinComma(std::vector<double>{0.5, 12, 1e-3}, [](double v) { return FormatShort(v); }), "0.5, 12, 0.001");
  struct Channel {
    std::string name;
  };
  EXPECT_EQ(JoinComma(std::vector<Channel>{{"a"}, {"b"}}, &Channel::name), "a, b");
  // Any separator (summary.csv's list of rates).
  EXPECT_EQ(Join(std::vector<double>{0.3, 0.015}, ";", [](double v) { return FormatShort(v); }), "0.3;0.015");
}

// A CSV header or a constraint label with ESC or a newline reached the
// terminal raw (and a NUL an SVG): Printable escapes control characters
// and bytes that are not UTF-8, and keeps the rest, multi-byte text included.
TEST(Printable, EscapesControlCharactersAndBytesThatAreNotUtf8) {
  EXPECT_EQ(Printable("R\x1b[2Jmeasured\nnext\r\tend"), "R\\x1b[2Jmeasured\\nnext\\r\\tend");
  EXPECT_EQ(Printable(std::string("a\0b\x7f", 4)), "a\\x00b\\x7f");
  EXPECT_EQ(Printable("λ 405 nm, Lv ≤ 1 cd/m², 😀"), "λ 405 nm, Lv ≤ 1 cd/m², 😀");
  EXPECT_EQ(Printable("\xff\xfe x \xc3"), "\\xff\\xfe x \\xc3");  // a lone lead byte at the end
  EXPECT_EQ(Printable("\xed\xa0\x80"), "\\xed\\xa0\\x80");        // a surrogate, U+D800
  EXPECT_EQ(Printable("\xc0\xaf"), "\\xc0\\xaf");                 // an overlong '/'
  // Whatever the bytes, the result is printable ASCII or valid UTF-8, and Printable keeps it.
  std::mt19937 rng(7);
  for (int trial = 0; trial < 1000; ++trial) {
    std::string bytes(16, '\0');
    for (char& c : bytes) c = static_cast<char>(rng() & 0xff);
    const std::string printable = Printable(bytes);
    for (char c : printable) EXPECT_FALSE(static_cast<unsigned char>(c) < 0x20 || c == 0x7f);
    EXPECT_EQ(Printable(printable), printable);
  }
}

TEST(Closest, NamesTheCandidateOneEditAwayAndNothingFarther) {
  // Random words, each mistyped by one edit of each kind: the word is found
  // among others of its length (random words of 8+ letters are many edits apart).
  std::mt19937_64 rng(11);
  auto letter = [&] { return static_cast<char>('a' + rng() % 26); };
  for (int trial = 0; trial < 2000; ++trial) {
    std::vector<std::string> words(12);
    for (std::string& w : words)
      for (std::size_t n = 8 + rng() % 8; w.size() < n;) w += letter();
    const std::string& word = words[rng() % words.size()];
    std::string typo = word;
    const std::size_t at = rng() % (word.size() - 1);
    switch (trial % 4) {
      case 0: typo.insert(typo.begin() + static_cast<std::ptrdiff_t>(at), letter()); break;
      case 1: typo.erase(at, 1); break;
      case 2: typo[at] = typo[at] == 'a' ? 'b' : 'a'; break;
      case 3:
        if (typo[at] == typo[at + 1]) typo[at] = typo[at] == 'a' ? 'b' : 'a';  // a swap that changes nothing
        std::swap(typo[at], typo[at + 1]);
        break;
    }
    ASSERT_EQ(Closest(typo, words), word) << typo;
  }
  // The command line's cases, and words too far from every candidate.
  EXPECT_EQ(Closest("--materal", {"--help", "--material", "--charge-s"}), "--material");
  EXPECT_EQ(Closest("--charg-s", {"--material", "--charge-s", "--decay-s"}), "--charge-s");
  EXPECT_EQ(Closest("rendr", {"render", "map", "batch", "status"}), "render");
  EXPECT_EQ(Closest("x", {"render", "map"}), "");
  EXPECT_EQ(Closest("schedule-curv", {"decay-curve", "charge-curve", "session", "map", "batch"}), "");
  EXPECT_EQ(Closest("anything", {}), "");
}

}  // namespace
}  // namespace phos
