// Encoder bridge of the VSA rig: reads up to four AS5048A magnetic encoders over SPI when the
// joint board asks on the serial line, as paper B's Arduino MEGA does. Frames (the host side is
// agents/dynamixel/src/encoder.rs):
//
//   request  A5 | N                                  read encoders 0..N-1
//   reply    5A | N | (ANGLE_L ANGLE_H FLAGS) x N | CHECKSUM
//
//   request  A6 | N                                  read load cells 0..N-1
//   reply    6A | N | (V_0 V_1 V_2 FLAGS) x N | CHECKSUM
//
// ANGLE: the AS5048A's 14-bit angle. FLAGS bit 0: the sensor's error flag or a parity error on
// SPI; bit 1: magnet out of range (diagnostics COMP high or low). CHECKSUM = ~(sum of every
// reply byte before it), low byte. N above the encoders wired is answered with N = 0, which
// the host does not accept: it times out naming the bridge (the config's channels are wrong).
//
// V: an HX711 load-cell amplifier's latest 24-bit conversion (channel A, gain 128), two's
// complement, low byte first. FLAGS bit 0: a new conversion since the previous reply (the
// HX711 converts at 10 Hz, or 80 Hz with its RATE pin high: between conversions the bridge
// repeats the last); bit 1: no HX711 answering (DOUT not low for 200 ms). The joint board's
// config gives each channel's zero and scale ([joint.torque_sensor]).
//
// Wiring (Arduino MEGA 2560): MISO 50, MOSI 51, SCK 52, chip selects in CS[] below; the
// AS5048A boards powered at 5 V (their 5 V mode) so the levels match. HX711s: DOUT and PD_SCK
// pins in HX_DOUT[] and HX_SCK[] below, VCC and VDD at 5 V, RATE high for 80 Hz. Not compiled by CI (no
// Arduino toolchain there): build with the Arduino IDE or arduino-cli for arduino:avr:mega.

#include <SPI.h>

const uint8_t CS[] = {10, 9, 8, 7};  // encoders 0..3 = the config's encoder.channel
const uint8_t MAX_N = sizeof(CS);
const SPISettings AS5048A(1000000, MSBFIRST, SPI_MODE1);  // CPOL 0, CPHA 1, 16-bit frames

const uint16_t READ_ANGLE = 0xFFFF;   // read 0x3FFF, parity bit set (even parity)
const uint16_t READ_DIAG = 0x7FFD;    // read 0x3FFD
const uint16_t CLEAR_ERROR = 0x4001;  // read 0x0001 clears the error flag
const uint16_t NOP = 0x0000;

// One 16-bit frame; the AS5048A answers a command in the next frame.
uint16_t frame(uint8_t cs, uint16_t command) {
  SPI.beginTransaction(AS5048A);
  digitalWrite(cs, LOW);
  uint16_t r = SPI.transfer16(command);
  digitalWrite(cs, HIGH);
  SPI.endTransaction();
  delayMicroseconds(1);  // CSn high time >= 350 ns
  return r;
}

bool parity_ok(uint16_t v) { return __builtin_parity(v) == 0; }

const uint8_t HX_DOUT[] = {22, 24, 26, 28};  // load cells 0..3 = the config's torque_sensor.channel
const uint8_t HX_SCK[] = {23, 25, 27, 29};
const uint8_t HX_N = sizeof(HX_DOUT);
int32_t hx_value[HX_N];
bool hx_fresh[HX_N];
uint32_t hx_last_ms[HX_N];  // when each last converted

// Polls every HX711: one that is ready (DOUT low) is read now — 24 bits MSB first, then one
// more pulse for channel A at gain 128 next time. Never waits for a conversion.
void poll_hx711() {
  for (uint8_t i = 0; i < HX_N; i++) {
    if (digitalRead(HX_DOUT[i]) != LOW) continue;
    uint32_t v = 0;
    noInterrupts();  // PD_SCK high for more than 60 us powers the HX711 down
    for (uint8_t b = 0; b < 24; b++) {
      digitalWrite(HX_SCK[i], HIGH);
      delayMicroseconds(1);
      v = (v << 1) | digitalRead(HX_DOUT[i]);
      digitalWrite(HX_SCK[i], LOW);
      delayMicroseconds(1);
    }
    digitalWrite(HX_SCK[i], HIGH);
    delayMicroseconds(1);
    digitalWrite(HX_SCK[i], LOW);
    interrupts();
    if (v & 0x800000) v |= 0xFF000000;  // sign-extend 24 -> 32 bits
    hx_value[i] = (int32_t)v;
    hx_fresh[i] = true;
    hx_last_ms[i] = millis();
  }
}

void reply_loads(uint8_t n) {
  if (n > HX_N) n = 0;
  uint8_t reply[3 + 4 * HX_N];
  uint8_t k = 0;
  reply[k++] = 0x6A;
  reply[k++] = n;
  uint32_t now = millis();
  for (uint8_t i = 0; i < n; i++) {
    int32_t v = hx_value[i];
    reply[k++] = v & 0xFF;
    reply[k++] = (v >> 8) & 0xFF;
    reply[k++] = (v >> 16) & 0xFF;
    uint8_t flags = hx_fresh[i] ? 1 : 0;
    if (now - hx_last_ms[i] > 200) flags |= 2;
    reply[k++] = flags;
    hx_fresh[i] = false;
  }
  uint8_t sum = 0;
  for (uint8_t j = 0; j < k; j++) sum += reply[j];
  reply[k++] = ~sum;
  Serial.write(reply, k);
}

void setup() {
  for (uint8_t i = 0; i < MAX_N; i++) {
    pinMode(CS[i], OUTPUT);
    digitalWrite(CS[i], HIGH);
  }
  for (uint8_t i = 0; i < HX_N; i++) {
    pinMode(HX_DOUT[i], INPUT_PULLUP);  // an unwired channel reads high: reported missing
    pinMode(HX_SCK[i], OUTPUT);
    digitalWrite(HX_SCK[i], LOW);
    hx_last_ms[i] = 0;
  }
  SPI.begin();
  Serial.begin(1000000);  // the config's encoder.baud
}

void loop() {
  poll_hx711();
  if (Serial.available() < 2) return;
  uint8_t kind = Serial.peek();
  if (kind != 0xA5 && kind != 0xA6) {  // not a request: skip the byte
    Serial.read();
    return;
  }
  Serial.read();
  uint8_t n = Serial.read();
  if (kind == 0xA6) {
    reply_loads(n);
    return;
  }
  if (n > MAX_N) n = 0;
  uint8_t reply[3 + 3 * MAX_N];
  uint8_t k = 0;
  reply[k++] = 0x5A;
  reply[k++] = n;
  for (uint8_t i = 0; i < n; i++) {
    frame(CS[i], READ_ANGLE);
    uint16_t angle = frame(CS[i], READ_DIAG);
    uint16_t diag = frame(CS[i], NOP);
    uint8_t flags = 0;
    if ((angle & 0x4000) || !parity_ok(angle)) {
      flags |= 1;
      frame(CS[i], CLEAR_ERROR);
      frame(CS[i], NOP);
    }
    if (diag & 0x0C00) flags |= 2;  // COMP high (bit 11) or COMP low (bit 10)
    uint16_t a = angle & 0x3FFF;
    reply[k++] = a & 0xFF;
    reply[k++] = a >> 8;
    reply[k++] = flags;
  }
  uint8_t sum = 0;
  for (uint8_t j = 0; j < k; j++) sum += reply[j];
  reply[k++] = ~sum;
  Serial.write(reply, k);
}
