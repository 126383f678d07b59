// Helpers shared by the probeless_dataset tests.
#pragma once

#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "probeless/dataset/source.h"
#include "probeless/msgs/msgs.h"

namespace probeless::dataset::testing {

// A fresh directory for one test, removed at the end.
class TempDir {
 public:
  TempDir() {
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    std::string name = std::string(info->test_suite_name()) + "_" + info->name();
    for (char& c : name) {
      if (c == '/') c = '_';
    }
    path_ = std::filesystem::path(::testing::TempDir()) /
            ("probeless_dataset_" + std::to_string(::getpid()) + "_" + name);
    std::filesystem::remove_all(path_);
    std::filesystem::create_directories(path_);
  }
  ~TempDir() { std::filesystem::remove_all(path_); }
  const std::string path() const { return path_.string(); }
  // `name` under the directory, creating its parent folders.
  std::string File(const std::string& name) const {
    const std::filesystem::path file = path_ / name;
    std::filesystem::create_directories(file.parent_path());
    return file.string();
  }

 private:
  std::filesystem::path path_;
};

inline void WriteText(const std::string& path, const std::string& text) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out << text;
}

// Every message of one pass.
inline std::vector<StreamMessage> Drain(Source& source) {
  std::vector<StreamMessage> messages;
  while (std::optional<StreamMessage> message = source.Next()) {
    messages.push_back(std::move(*message));
  }
  return messages;
}

// The what() of the DatasetError `action` throws, or "no error".
inline std::string ErrorOf(const std::function<void()>& action) {
  try {
    action();
  } catch (const DatasetError& e) {
    return e.what();
  }
  return "no error";
}

template <class M>
msgs::ReadView<M> View(const StreamMessage& message) {
  return msgs::ReadMessage<M>(message.message.bytes());
}

}  // namespace probeless::dataset::testing
