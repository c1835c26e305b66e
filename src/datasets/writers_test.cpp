#include <gtest/gtest.h>
TEST(Writers, Placeholder) {}
