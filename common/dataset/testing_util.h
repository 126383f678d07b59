// Helpers shared by the probeless_dataset tests.
#pragma once

#include <gtest/gtest.h>

#include <optional>
#include <string>
#include <vector>

#include "probeless/dataset/source.h"
#include "probeless/msgs/msgs.h"
#include "probeless/testing/testing.h"

namespace probeless::dataset::testing {

// A fresh directory for one test, removed at the end (path(), File(name)).
class TempDir : public probeless::testing::TempDir {
 public:
  TempDir() : probeless::testing::TempDir("probeless_dataset") {}
};

using probeless::testing::WriteText;

// Every message of one pass.
inline std::vector<StreamMessage> Drain(Source& source) {
  std::vector<StreamMessage> messages;
  while (std::optional<StreamMessage> message = source.Next()) {
    messages.push_back(std::move(*message));
  }
  return messages;
}

template <class M>
msgs::ReadView<M> View(const StreamMessage& message) {
  return msgs::ReadMessage<M>(message.message.bytes());
}

}  // namespace probeless::dataset::testing
