// Options described once (core/options.h): range checks that name the flag, nested tables,
// choices, malformed tables refused, and options to and from JSON.
#include "carousel/core/options.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "carousel/core/error.h"
#include "carousel/core/options_json.h"

namespace carousel {
namespace {

using ::testing::HasSubstr;
using ::testing::ThrowsMessage;

enum class Mode { kFast, kGood };

struct Inner {
  int faces = 4500;
  double fraction = 0.5;
  Mode mode = Mode::kGood;
  static const OptionTable<Inner>& Fields() {
    static const OptionTable<Inner> table = [] {
      OptionTable<Inner> t;
      t.Add(&Inner::faces, {.name = "faces", .help = "faces", .min = 100});
      t.Add(&Inner::fraction,
            {.name = "fraction", .help = "a fraction", .min = 0, .max = 1, .min_exclusive = true});
      t.AddChoice(&Inner::mode, {.name = "mode", .help = "how"},
                  {{"fast", Mode::kFast}, {"good", Mode::kGood}});
      return t;
    }();
    return table;
  }
};

struct Outer {
  Inner inner;
  int size = 0;
  std::vector<double> angles = {20.0};
  static const OptionTable<Outer>& Fields() {
    static const OptionTable<Outer> table = [] {
      OptionTable<Outer> t;
      t.Include(&Outer::inner, Inner::Fields());
      t.Add(&Outer::size, {.name = "size",
                           .help = "atlas side",
                           .unit = "texels",
                           .min = 64,
                           .max = 16384,
                           .special = 0,
                           .special_meaning = "automatic"});
      t.Add(&Outer::angles, {.name = "angles", .help = "elevations", .min = -10, .max = 85});
      return t;
    }();
    return table;
  }
};

TEST(OptionsTest, ChecksNameTheFlagAndTheRange) {
  Outer o;
  EXPECT_NO_THROW(Outer::Fields().Check(o));
  o.inner.faces = 50;
  EXPECT_THAT([&] { Outer::Fields().Check(o); },
              ThrowsMessage<InvalidArgument>(HasSubstr("--faces must be >= 100, got 50")));
  o.inner.faces = 100;
  o.inner.fraction = 0.0;  // excluded bound
  EXPECT_THAT([&] { Outer::Fields().Check(o); },
              ThrowsMessage<InvalidArgument>(HasSubstr("--fraction must be (0, 1], got 0")));
  o.inner.fraction = std::numeric_limits<double>::quiet_NaN();
  EXPECT_THROW(Outer::Fields().Check(o), InvalidArgument);
  o.inner.fraction = 1.0;
  o.size = 20;
  EXPECT_THAT([&] { Outer::Fields().Check(o); },
              ThrowsMessage<InvalidArgument>(
                  HasSubstr("--size must be 64..16384 texels, or 0 = automatic, got 20")));
  o.size = 0;  // the special value
  EXPECT_NO_THROW(Outer::Fields().Check(o));
  o.angles = {20.0, 95.0};  // each element of a list
  EXPECT_THAT([&] { Outer::Fields().Check(o); },
              ThrowsMessage<InvalidArgument>(HasSubstr("--angles must be -10..85, got 95")));
}

TEST(OptionsTest, NestedFieldsReachTheirMembers) {
  Outer o;
  const auto& faces = Outer::Fields().Find("faces");
  *std::get<int*>(faces.ref(o)) = 1234;
  EXPECT_EQ(o.inner.faces, 1234);
  const auto& mode = Outer::Fields().Find("mode");
  EXPECT_TRUE(mode.is_choice());
  EXPECT_EQ(mode.text_get(o), "good");
  mode.text_set(o, "fast");
  EXPECT_EQ(o.inner.mode, Mode::kFast);
  EXPECT_THAT([&] { mode.text_set(o, "best"); },
              ThrowsMessage<InvalidArgument>(HasSubstr("--mode must be fast or good, got 'best'")));
  EXPECT_EQ(Outer::Fields().Only({"size", "faces"}).fields().size(), 2u);
  EXPECT_EQ(Outer::Fields().Without({"size"}).fields().size(), 4u);
  EXPECT_THROW(Outer::Fields().Find("nothing"), std::logic_error);
}

TEST(OptionsJsonTest, RoundTripsEveryKindOfFieldByItsFlagName) {
  Outer o;
  o.inner.faces = 777;
  o.inner.fraction = 0.25;
  o.inner.mode = Mode::kFast;
  o.size = 2048;
  o.angles = {10.0, 45.5};
  const nlohmann::json j = OptionsToJson(Outer::Fields(), o);
  EXPECT_EQ(j.at("faces"), 777);
  EXPECT_EQ(j.at("mode"), "fast");
  EXPECT_EQ(j.at("angles"), nlohmann::json::array({10.0, 45.5}));
  Outer back;
  OptionsFromJson(Outer::Fields(), nlohmann::json::parse(j.dump()), &back, "run.json");
  EXPECT_EQ(back.inner.faces, 777);
  EXPECT_EQ(back.inner.fraction, 0.25);
  EXPECT_EQ(back.inner.mode, Mode::kFast);
  EXPECT_EQ(back.size, 2048);
  EXPECT_EQ(back.angles, o.angles);
}

TEST(OptionsJsonTest, MissingFieldsKeepTheirDefaultsAndBadValuesNameTheFileAndField) {
  Outer o;
  OptionsFromJson(Outer::Fields(), nlohmann::json{{"size", 512}}, &o, "run.json");
  EXPECT_EQ(o.size, 512);
  EXPECT_EQ(o.inner.faces, 4500);
  EXPECT_EQ(o.inner.mode, Mode::kGood);
  EXPECT_THAT(
      [&] {
        OptionsFromJson(Outer::Fields(), {{"faces", "many"}}, &o, "run.json");
      },
      ThrowsMessage<FormatError>(
          ::testing::AllOf(HasSubstr("run.json"), HasSubstr("option 'faces'"))));
  EXPECT_THAT(
      [&] {
        OptionsFromJson(Outer::Fields(), {{"mode", "best"}}, &o, "run.json");
      },
      ThrowsMessage<FormatError>(HasSubstr("--mode must be fast or good")));
  EXPECT_THROW(OptionsFromJson(Outer::Fields(), nlohmann::json::array(), &o, "run.json"),
               FormatError);
}

TEST(OptionsTest, MalformedTablesAreRefused) {
  OptionTable<Inner> t;
  t.Add(&Inner::faces, {.name = "faces"});
  EXPECT_THROW(t.Add(&Inner::fraction, {.name = "faces"}), std::logic_error);
  EXPECT_THROW(t.Add(&Inner::fraction, {.name = "Fraction"}), std::logic_error);
  EXPECT_THROW(t.Add(&Inner::fraction, {.name = ""}), std::logic_error);
  EXPECT_THROW(OptionTable<Outer>()
                   .Include(&Outer::inner, Inner::Fields())
                   .Include(&Outer::inner, Inner::Fields()),
               std::logic_error);
}

}  // namespace
}  // namespace carousel
